//! Writes the seed corpora: `seeds DIR` fills `DIR/<target>/seed-*` for every target (files of
//! the same name are replaced, anything else in DIR is left alone). Run by `scripts/fuzz.sh`
//! before each fuzzing run; the seeds follow the protocol because they are encoded by it.

use std::path::Path;

use chladni_fuzz::{envelope, message, sample_requests, sample_responses, wire};

fn main() -> std::io::Result<()> {
    let Some(dir) = std::env::args().nth(1) else {
        eprintln!("usage: seeds DIR");
        std::process::exit(2);
    };
    let dir = Path::new(&dir);
    let mut written = 0;
    for (target, seeds) in [("frame_decoder", frame_decoder())] {
        let sub = dir.join(target);
        std::fs::create_dir_all(&sub)?;
        for (name, bytes) in &seeds {
            std::fs::write(sub.join(format!("seed-{name}")), bytes)?;
        }
        written += seeds.len();
    }
    println!("seeds: {written} file(s) under {}", dir.display());
    Ok(())
}

/// `mode · payload` inputs of `fuzz_targets/frame_decoder.rs`.
fn frame_decoder() -> Vec<(String, Vec<u8>)> {
    let with_mode = |mode: u8, bytes: Vec<u8>| [vec![mode], bytes].concat();
    let mut seeds = Vec::new();
    for (i, r) in sample_requests().into_iter().enumerate() {
        let env = envelope(0x1234_5678, 1000 + i as u32, r);
        seeds.push((format!("wire-req-{i:02}"), with_mode(0, wire(&env))));
        seeds.push((format!("msg-req-{i:02}"), with_mode(1, message(&env))));
    }
    for (i, r) in sample_responses().into_iter().enumerate() {
        let env = envelope(0x1234_5678, 2000 + i as u32, r);
        seeds.push((format!("wire-resp-{i:02}"), with_mode(0, wire(&env))));
        seeds.push((format!("msg-resp-{i:02}"), with_mode(1, message(&env))));
    }
    // Two frames after garbage and an overlong frame.
    let mut stream = vec![0x11; 40];
    stream.push(0);
    stream.extend(vec![0x22; 1100]);
    stream.extend(wire(&envelope(7, 8, sample_requests()[1].clone())));
    stream.extend(wire(&envelope(7, 9, sample_requests()[4].clone())));
    seeds.push(("wire-garbage-then-frames".into(), with_mode(0, stream)));
    // Mode 2: session, id, flags (request/response, edit before/after the CRC), index, edits.
    for flags in 0..4u8 {
        let mut m = vec![2, 1, 0, 0, 0, 2, 0, 0, 0, flags, 4, 0, 3];
        m.extend([0, 5, 0, 3, 1, 9, 0, 0x80]);
        seeds.push((format!("mutated-{flags}"), m));
    }
    seeds
}
