//! Writes the seed corpora: `seeds DIR` fills `DIR/<target>/seed-*` for every target (files of
//! the same name are replaced, anything else in DIR is left alone). Run by `scripts/fuzz.sh`
//! before each fuzzing run; the seeds follow the protocol because they are encoded by it.

use std::path::Path;

use chladni_fuzz::{envelope, message, sample_requests, sample_responses, wire};
use chladni_shared::icd::link::Request;
use chladni_shared::icd::store::PlanRef;

fn main() -> std::io::Result<()> {
    let Some(dir) = std::env::args().nth(1) else {
        eprintln!("usage: seeds DIR");
        std::process::exit(2);
    };
    let dir = Path::new(&dir);
    let mut written = 0;
    let targets = [
        ("frame_decoder", frame_decoder()),
        ("request_handler", request_handler()),
        ("plan_store", plan_store()),
        ("part_analysis", part_analysis()),
    ];
    for (target, seeds) in targets {
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

/// Programs of `fuzz_targets/request_handler.rs`: step bytes as its doc says.
fn request_handler() -> Vec<(String, Vec<u8>)> {
    let samples = sample_requests();
    let index = |want: &dyn Fn(&Request) -> bool| {
        samples.iter().position(want).expect("a sample request of that kind") as u16
    };
    // Step 2: a sample request from session `s` (0..3) with id `id`, unedited.
    let ask = |s: u8, i: u16, id: u32| -> Vec<u8> {
        [vec![2, s], i.to_le_bytes().to_vec(), id.to_le_bytes().to_vec(), vec![0]].concat()
    };
    let mut seeds = Vec::new();
    // Every sample request, once, from the first session.
    let every: Vec<u8> =
        (0..samples.len() as u16).flat_map(|i| ask(0, i, 100 + i as u32)).collect();
    seeds.push(("every-request".into(), every));
    // Upload, list, run, play, telemetry, stop, delete.
    let begin = index(&|r| matches!(r, Request::UploadBegin(b) if b.slot == Some(4)));
    let chunk0 =
        index(&|r| matches!(r, Request::UploadChunk(c) if c.index == 0 && c.steps.len() > 1));
    let chunk1 = index(&|r| matches!(r, Request::UploadChunk(c) if c.index == 1));
    let commit = index(&|r| matches!(r, Request::UploadCommit(_)));
    let list = index(&|r| matches!(r, Request::ListPlans(_)));
    let run = index(&|r| matches!(r, Request::RunPlan(p) if p.plan == PlanRef::Slot(4)));
    let subscribe = index(&|r| matches!(r, Request::Subscribe(_)));
    let stop = index(&|r| matches!(r, Request::Stop(_)));
    let delete = index(&|r| matches!(r, Request::DeletePlan(d) if d.plan == PlanRef::Slot(4)));
    let status = index(&|r| matches!(r, Request::Status(_)));
    let mut upload = Vec::new();
    for (id, i) in [begin, chunk0, chunk1, commit, list, run].into_iter().enumerate() {
        upload.extend(ask(0, i, 1 + id as u32));
    }
    upload.extend([6, 8]);
    upload.extend(ask(0, subscribe, 20));
    upload.extend([7, 5, 100, 0, 7]);
    upload.extend(ask(1, status, 21));
    upload.extend(ask(1, stop, 22));
    upload.extend([6, 15]);
    upload.extend(ask(0, delete, 23));
    upload.extend(ask(0, list, 24));
    seeds.push(("upload-run-delete".into(), upload));
    // Ownership: a second session is refused, then takes over after the lease.
    let drive = index(&|r| matches!(r, Request::Drive(_)));
    let mut owners = Vec::new();
    owners.extend(ask(0, drive, 1));
    owners.extend(ask(1, drive, 2));
    owners.extend([5, 0xa0, 0x0f]); // 4000 ms
    owners.extend(ask(1, drive, 3));
    owners.extend(ask(0, drive, 4));
    seeds.push(("ownership".into(), owners));
    // Garbage, then a request.
    let mut garbage = vec![0, 40, 0];
    garbage.extend([0x55; 40]);
    garbage.extend(ask(2, status, 9));
    seeds.push(("garbage-then-request".into(), garbage));
    seeds
}

/// Programs of `fuzz_targets/plan_store.rs`: operation bytes as its doc says.
fn plan_store() -> Vec<(String, Vec<u8>)> {
    // Upload: name, repeat, size (and count), seed (4), valid; slot choice (0: any free slot),
    // mischief.
    let upload = |name: u8, size: u8, slot: Option<u8>| -> Vec<u8> {
        let mut op = vec![0, name, 0, size];
        if size & 0x80 != 0 {
            op.push(199); // 200 steps
        }
        op.extend([7, 0, 0, 0, 0]);
        match slot {
            None => op.push(0),
            Some(slot) => op.extend([1, slot]),
        }
        op.push(0);
        op
    };
    let cut = |op: Vec<u8>, after: u16, noise: u8| -> Vec<u8> {
        [vec![op[0] | 0x80], after.to_le_bytes().to_vec(), vec![noise], op[1..].to_vec()].concat()
    };
    let (list, reboot) = (vec![2], vec![5]);
    let load_name = |name: u8| vec![3, 1, name];
    let delete_slot = |slot: u8| vec![1, 0, slot];
    let mut seeds = Vec::new();
    let mut life = Vec::new();
    for op in [
        upload(0, 40, None),
        upload(1, 3, Some(64)),
        list.clone(),
        load_name(0),
        vec![4, 10, 0, 10, 0, 0, 1, 100, 0, 0, 0, 1, 0],
        reboot.clone(),
        delete_slot(0),
        upload(2, 0x80 | 0x20, Some(5)),
        list.clone(),
    ] {
        life.extend(op);
    }
    seeds.push(("upload-list-load-config-delete".into(), life));
    // Cuts inside an upload that replaces a plan, and inside a delete.
    for (i, after) in [0u16, 3, 9, 20, 40, 80].into_iter().enumerate() {
        let mut prog = upload(0, 40, Some(2));
        prog.extend(cut(upload(0, 33, Some(2)), after, 0x5a));
        prog.extend(list.clone());
        seeds.push((format!("cut-upload-{i}"), prog));
        let mut prog = upload(1, 10, None);
        prog.extend(cut(delete_slot(0), after / 8, 0xa5));
        seeds.push((format!("cut-delete-{i}"), prog));
    }
    seeds
}

/// Inputs of `fuzz_targets/part_analysis.rs`: each law with unit and 1:2 gains, over a raw
/// 40 × 10 rectangle (raw rings, 2⁻⁸ mm units) and a valid star part with a hole.
fn part_analysis() -> Vec<(String, Vec<u8>)> {
    let mut seeds = Vec::new();
    for law in 0..3u8 {
        for ratio in [3u8, 1] {
            // law, wavelength (1000 mm), gains (unused: ratio picks), sign byte, ratio.
            let mut head = vec![law];
            head.extend(1000u32.to_le_bytes());
            head.push(32);
            head.extend([0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, ratio]);
            let mut rect = head.clone();
            rect.extend([0, 1, 4, 24]);
            for (x, y) in [(0i32, 0i32), (40 << 8, 0), (40 << 8, 10 << 8), (0, 10 << 8)] {
                rect.extend(x.to_le_bytes());
                rect.extend(y.to_le_bytes());
            }
            seeds.push((format!("rect-law{law}-ratio{ratio}"), rect));
            let mut star = head;
            // Valid part, scale byte, 8 vertices, their 16 bytes; a 5-vertex hole, its 10;
            // the start angle for `align`, and the determinism check asked for.
            star.extend([1, 29, 5]);
            star.extend((0..16).map(|i| (i * 37 % 256) as u8));
            star.push(5);
            star.extend((0..10).map(|i| (i * 91 % 256) as u8));
            star.extend([0, 0, 0, 0x40, 7]);
            seeds.push((format!("star-law{law}-ratio{ratio}"), star));
        }
    }
    seeds
}
