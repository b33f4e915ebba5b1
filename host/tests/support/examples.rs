//! The example parts and plates of the source tree, and plates written inline, for the
//! planner's integration tests. Each test binary compiles this module and uses part of it.
#![allow(dead_code)]

use std::path::Path;

use chladni::model::part::Part;
use chladni::model::plate::PlateModel;
use chladni::model::plate_file::PlateFile;

/// The workspace root.
pub fn root() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

/// `examples/parts/NAME`.
pub fn part(name: &str) -> Part {
    Part::load(&root().join("examples/parts").join(name)).unwrap()
}

/// `examples/plates/NAME`.
pub fn plate(name: &str) -> PlateModel {
    PlateModel::load(&root().join("examples/plates").join(name)).unwrap()
}

/// A 300 × 200 mm plate with the `[[mode]]` entries `modes`.
pub fn plate_text(modes: &str) -> PlateModel {
    let text = format!("[plate]\nname = \"t\"\nsize_mm = [300.0, 200.0]\n{modes}");
    PlateModel::from_file(&PlateFile::parse(&text, "t").unwrap()).unwrap()
}
