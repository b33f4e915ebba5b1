//! The link's costs against the QEMU controller: upload + commit of a 256-step plan (target
//! under 100 ms), the same while the drive runs (does the store starve the drive? underruns
//! are counted), and a ping for scale.
//!
//! `cargo bench -p chladni-e2e --bench link` (builds the QEMU firmware if needed). QEMU's clock
//! follows the host's, so these are wall-clock times on this machine, with QEMU's semihosting
//! file flash; a real board's flash is faster to read and slower to write.

use std::time::{Duration, Instant};

use chladni_e2e::start_emulator;
use chladni_shared::icd::plan::{MAX_STEPS, Plan, Step};
use chladni_shared::icd::store::SCRATCH_SLOT;

/// A 256-step plan whose steps all differ (so nothing compresses or repeats).
fn plan(seed: u32) -> Plan {
    let step = |i: u32| Step {
        freq_mhz: 50_000 + (i * 7_919 + seed * 104_729) % 1_900_000,
        level: chladni_shared::icd::plan::Level::Drive(((i * 131 + seed) % 30_000) as u16),
        duration_ms: 5 + i % 40,
        ramp_ms: i % 5,
    };
    Plan {
        name: format!("bench-{seed}").as_str().try_into().expect("short name"),
        repeat: 1,
        steps: (0..MAX_STEPS as u32).map(step).collect(),
    }
}

/// min / median / 90th percentile / max, ms.
fn summary(label: &str, mut times: Vec<Duration>) {
    times.sort();
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    let at = |q: f64| ms(times[((times.len() - 1) as f64 * q).round() as usize]);
    println!(
        "{label:<44} n={:<3} min {:7.2} ms  median {:7.2} ms  p90 {:7.2} ms  max {:7.2} ms",
        times.len(),
        ms(times[0]),
        at(0.5),
        at(0.9),
        ms(*times.last().expect("timed at least once"))
    );
}

fn main() {
    let emulator = start_emulator("bench-link");
    let mut client = emulator.connect("bench link").expect("connect");

    let pings: Vec<Duration> = (0..50).map(|_| client.ping().expect("ping")).collect();
    summary("ping", pings);

    // The first uploads after boot pay for sequential-storage learning where items are; then
    // uploads replace plans again and again (garbage collection goes round the flash).
    let mut first = Vec::new();
    let mut later = Vec::new();
    for i in 0..60u32 {
        let p = plan(i);
        let slot = Some((i % 8) as u8);
        let t = Instant::now();
        client.upload(&p, slot, |_, _| {}).expect("upload");
        if i < 10 { first.push(t.elapsed()) } else { later.push(t.elapsed()) }
    }
    summary("upload+commit 256 steps, first 10 after boot", first);
    summary("upload+commit 256 steps, next 50", later);

    // Where an upload's time goes: one round trip per request, by kind.
    let p = plan(500);
    let (mut begin, mut chunks, mut commit) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..10 {
        let t = Instant::now();
        client
            .call(chladni_shared::icd::store::UploadBegin {
                slot: Some(9),
                name: p.name.clone(),
                repeat: 1,
                steps: p.steps.len() as u16,
                crc: chladni_shared::icd::store::plan_crc(&p),
            })
            .expect("begin");
        begin.push(t.elapsed());
        for (index, c) in p.steps.chunks(chladni_shared::icd::store::CHUNK_STEPS).enumerate() {
            let steps = heapless::Vec::from_slice(c).expect("chunk");
            let t = Instant::now();
            let chunk = chladni_shared::icd::store::UploadChunk { index: index as u16, steps };
            client.call(chunk).expect("chunk");
            chunks.push(t.elapsed());
        }
        let t = Instant::now();
        client.call(chladni_shared::icd::link::UploadCommit).expect("commit");
        commit.push(t.elapsed());
    }
    summary("  of which UploadBegin", begin);
    summary("  of which UploadChunk (32 steps, ~400 bytes)", chunks);
    summary("  of which UploadCommit", commit);

    // While the drive runs: the drive must not run dry because of the store.
    let before = client.status().expect("status").underruns;
    client.drive(180_000, chladni_shared::icd::plan::Level::Drive(8_000)).expect("drive");
    let mut driving = Vec::new();
    for i in 0..20u32 {
        let t = Instant::now();
        client.upload(&plan(100 + i), Some(SCRATCH_SLOT), |_, _| {}).expect("upload");
        driving.push(t.elapsed());
    }
    let after = client.status().expect("status").underruns;
    client.stop().expect("stop");
    summary("upload+commit 256 steps while driving", driving);
    println!("underruns during those uploads: {}", after - before);
}
