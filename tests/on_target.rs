//! On-target tests: runs the firmware's defmt-test suite on Cortex-M in QEMU
//! (`scripts/firmware.sh test qemu`) and checks that every shared test vector produced the
//! same digest there as here on the host — the same code giving the same bits.

use std::collections::BTreeMap;
use std::process::Command;

use chladni_e2e::root;

#[test]
fn firmware_tests_pass_in_qemu_and_vectors_match_the_host_bit_for_bit() {
    let out = Command::new(root().join("scripts/firmware.sh"))
        .args(["test", "qemu"])
        .current_dir(root())
        .output()
        .expect("run scripts/firmware.sh test qemu");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "on-target tests failed ({}):\n{stdout}\n{stderr}", out.status);

    let on_target: BTreeMap<&str, u64> = stdout
        .lines()
        .filter_map(|line| {
            let mut words = line.split_whitespace();
            (words.next()? == "vector").then_some(())?;
            let name = words.next()?;
            let digest = u64::from_str_radix(words.next()?, 16).ok()?;
            Some((name, digest))
        })
        .collect();

    for (name, vector) in chladni_shared::vectors::ALL {
        let host = vector().unwrap_or_else(|e| panic!("vector {name} failed on the host: {e}"));
        let target = on_target
            .get(name)
            .unwrap_or_else(|| panic!("vector {name} missing from the QEMU run:\n{stdout}"));
        assert_eq!(
            *target, host,
            "vector {name}: Cortex-M digest {target:016x} != host digest {host:016x}"
        );
    }
    assert_eq!(
        on_target.len(),
        chladni_shared::vectors::ALL.len(),
        "unexpected vectors: {on_target:?}"
    );
    println!("{} vectors identical on host and Cortex-M", on_target.len());
}
