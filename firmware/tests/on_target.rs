//! On-target tests, run on Cortex-M in QEMU by `scripts/firmware.sh test qemu`
//! (defmt-test; the verdict leaves QEMU through semihosting's exit code).
//!
//! `shared_vectors` prints `vector <name> <digest>` for every `chladni_shared::vectors`
//! entry; the host test `tests/on_target.rs` compares those digests with its own, which proves
//! the shared code gives the same bits on both sides.
#![no_std]
#![no_main]

use chladni_firmware as _; // board support: defmt logger, panic handler, exit

#[defmt_test::tests]
mod tests {
    use chladni_firmware::app::drive::DriveShared;
    use chladni_firmware::app::link::{Identity, handle};
    use chladni_shared::link::{Board, PROTOCOL_VERSION, Request, Response};

    #[test]
    fn shared_vectors() {
        for (name, vector) in chladni_shared::vectors::ALL {
            match vector() {
                Ok(digest) => defmt::println!("vector {=str} {=u64:016x}", name, digest),
                Err(why) => defmt::panic!("vector {=str} failed: {=str}", name, why),
            }
        }
    }

    #[test]
    fn ping_echoes_nonce() {
        let id = Identity { board: Board::Qemu };
        assert_eq!(
            handle(&id, &DriveShared::new(), &Request::Ping { nonce: 0x5eed }),
            Response::Pong { nonce: 0x5eed }
        );
    }

    #[test]
    fn info_names_board_and_protocol() {
        let id = Identity { board: Board::Qemu };
        match handle(&id, &DriveShared::new(), &Request::GetInfo) {
            Response::Info(info) => {
                assert_eq!(info.board, Board::Qemu);
                assert_eq!(info.protocol_version, PROTOCOL_VERSION);
                assert_eq!(info.firmware_version.as_str(), chladni_firmware::FIRMWARE_VERSION);
            }
            other => defmt::panic!("unexpected {}", other),
        }
    }

    #[test]
    fn drive_core_runs_a_plan_to_idle() {
        use chladni_firmware::app::drive::{Command, DriveCore};
        use chladni_shared::plan::{Plan, Step};
        use chladni_shared::runner::{BLOCK_LEN, DriveState};
        let shared = DriveShared::new();
        let mut plan =
            Plan { name: heapless::String::new(), repeat: 1, steps: heapless::Vec::new() };
        for (f, d) in [(100_000, 12), (200_000, 8)] {
            let s = Step { freq_mhz: f, amplitude_q15: 10_000, duration_ms: d, ramp_ms: 2 };
            plan.steps.push(s).unwrap();
        }
        shared.submit(Command::RunPlan(plan)).unwrap();
        let mut core = DriveCore::new(&shared);
        let mut block = [0u16; BLOCK_LEN];
        let mut steps_seen = [false; 2];
        for _ in 0..100 {
            core.refill(&mut block);
            let s = shared.status();
            if let Some(i) = s.step {
                steps_seen[i as usize] = true;
            }
            if s.state == DriveState::Idle {
                break;
            }
        }
        let s = shared.status();
        assert_eq!(s.state, DriveState::Idle);
        assert_eq!(steps_seen, [true, true]);
        // 20 ms of steps + the 20 ms ramp to zero at 50 samples/ms.
        assert_eq!(s.elapsed_samples, 40 * 50);
    }
}
