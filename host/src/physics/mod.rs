//! Physics models behind the field model of DESIGN §2.

pub mod string;
