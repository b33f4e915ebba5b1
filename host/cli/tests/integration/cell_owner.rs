//! The cell's link owner against the controller in QEMU: a run goes busy then done (never the
//! last run's done first), bad slots and empty slots are named, a stopped run reads idle, a
//! killed controller reads error within seconds, and a restarted one is picked up again. The
//! stale-busy case: the controller is killed mid-run and started again on the same flash (its
//! run numbers start over): the cell follows it (error naming the lost run, never busy), and a
//! stop resolves it to idle. A controller that hangs (QEMU frozen) reads link down, and thawed it
//! runs the cell's next plan. Dropped, the cell's owner ends and releases the controller at once.

use std::time::{Duration, Instant};

use chladni_cell::{Cell, CellError, CellState, CellStatus};

use crate::support;
use support::emu;

const SLOT: u8 = 2;

/// The states published until `wanted` holds (that status last); panics after `limit`.
async fn until(
    cell: &Cell,
    limit: Duration,
    wanted: impl Fn(&CellStatus) -> bool,
) -> Vec<CellStatus> {
    let mut watch = cell.watch();
    let deadline = Instant::now() + limit;
    let mut seen = vec![watch.borrow_and_update().clone()];
    while !wanted(seen.last().unwrap()) {
        let left = deadline.saturating_duration_since(Instant::now());
        let changed = tokio::time::timeout(left, watch.changed()).await;
        assert!(
            matches!(changed, Ok(Ok(()))),
            "gave up after {limit:?}; last {:?}",
            seen.last().map(|s| (s.state, &s.error))
        );
        seen.push(watch.borrow_and_update().clone());
    }
    seen
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_owner_runs_stops_and_reports_a_lost_and_found_link() {
    let mut emu = emu::emulator_for("cell-owner", Duration::from_secs(120));
    // Two steps of 800 ms, open loop.
    emu::upload(&emu, &emu::open_loop_plan("owner", &[110_000, 140_000], 8_000, 800), SLOT);
    let cell = Cell::start(&emu.address(), "cell_owner test");
    until(&cell, Duration::from_secs(10), |s| s.link_up && s.state == CellState::Idle).await;

    let started = cell.run(u32::from(SLOT), None).await.expect("run");
    assert_eq!((started.slot, started.plan.as_str()), (SLOT, "owner"));
    // Published before the answer: busy at once.
    assert_eq!(cell.status().state, CellState::Busy);
    let seen = until(&cell, Duration::from_secs(10), |s| s.state != CellState::Busy).await;
    assert_eq!(seen.last().unwrap().state, CellState::Done, "{:?}", seen.last().unwrap().error);
    assert_eq!(seen.last().unwrap().last_run, Some(started.run));

    assert!(matches!(cell.run(70, None).await, Err(CellError::BadSlot { slot: 70 })));
    match cell.run(9, None).await {
        Err(CellError::NoPlan { slot: 9, stored }) => assert_eq!(stored, SLOT.to_string()),
        other => panic!("slot 9 holds no plan, got {other:?}"),
    }
    let (plans, _) = cell.plans().expect("plans");
    assert_eq!(plans.iter().map(|p| p.slot).collect::<Vec<_>>(), [SLOT]);

    let second = cell.run(u32::from(SLOT), None).await.expect("run again");
    // Stopped while the device reports it running.
    until(&cell, Duration::from_secs(5), |s| {
        s.device.as_ref().is_some_and(|d| d.run == second.run)
    })
    .await;
    let stop = cell.stop().await.expect("stop");
    assert!(stop > started.run);
    let seen = until(&cell, Duration::from_secs(5), |s| s.state != CellState::Busy).await;
    assert_eq!(seen.last().unwrap().state, CellState::Idle, "a stopped run reads idle");

    // Killed mid-run: the run is lost with the controller.
    let lost_run = cell.run(u32::from(SLOT), None).await.expect("run before the power cut");
    until(&cell, Duration::from_secs(5), |s| {
        s.device.as_ref().is_some_and(|d| d.run == lost_run.run)
    })
    .await;
    assert_eq!(cell.status().state, CellState::Busy);
    emu.kill();
    let killed = Instant::now();
    let seen = until(&cell, Duration::from_secs(8), |s| s.state == CellState::Error).await;
    let lost = seen.last().unwrap();
    assert!(!lost.link_up);
    assert!(lost.error.as_deref().unwrap().contains("link down"), "{:?}", lost.error);
    eprintln!("link loss seen after {:.1} s", killed.elapsed().as_secs_f64());
    assert!(matches!(cell.run(u32::from(SLOT), None).await, Err(CellError::LinkDown { .. })));

    emu.restart().expect("restart the emulator");
    let back = Instant::now();
    let seen = until(&cell, Duration::from_secs(15), |s| {
        s.link_up
            && s.device.is_some()
            && s.error.as_deref().is_some_and(|e| !e.contains("link down"))
    })
    .await;
    eprintln!("link back after {:.1} s", back.elapsed().as_secs_f64());
    // Never a stale busy once the link is up again: the device restarted at run 0.
    assert!(seen.iter().all(|s| !(s.link_up && s.state == CellState::Busy)), "stale busy");
    let after = seen.last().unwrap();
    assert_eq!(after.state, CellState::Error);
    let why = after.error.as_deref().unwrap();
    assert!(why.contains("restarted") && why.contains(&format!("run {}", lost_run.run)), "{why}");
    // A stop acknowledges it: the cell reads the device's idle.
    cell.stop().await.expect("stop after the restart");
    let seen = until(&cell, Duration::from_secs(5), |s| s.state == CellState::Idle).await;
    assert_eq!(seen.last().unwrap().last_run, None);
    // And the cell runs again on the restarted controller.
    let again = cell.run(u32::from(SLOT), None).await.expect("run after the restart");
    assert!(
        again.run < lost_run.run,
        "the run numbers started over: {} {}",
        again.run,
        lost_run.run
    );
    let seen = until(&cell, Duration::from_secs(10), |s| s.state == CellState::Done).await;
    assert_eq!(seen.last().unwrap().last_run, Some(again.run));

    // Frozen, as a controller that hangs with its link open: the cell calls the link down
    // within its answer timeout and refuses runs. Thawed, the controller reads the requests
    // buffered meanwhile and answers them late; the cell's new session takes none of those
    // answers for its own, and its next run is accepted and runs to done. (QEMU's clock jumps
    // over the freeze, so the old session's lease has run out by then: this does not test the
    // release; the drop below does.)
    emu.pause();
    let frozen = Instant::now();
    let seen = until(&cell, Duration::from_secs(8), |s| !s.link_up).await;
    let hung = seen.last().unwrap();
    assert!(hung.error.as_deref().unwrap().contains("link down"), "{:?}", hung.error);
    eprintln!("hang seen after {:.2} s", frozen.elapsed().as_secs_f64());
    assert!(matches!(cell.run(u32::from(SLOT), None).await, Err(CellError::LinkDown { .. })));
    emu.resume();
    let thawed = Instant::now();
    until(&cell, Duration::from_secs(10), |s| s.link_up && s.device.is_some()).await;
    eprintln!("link back after the hang in {:.2} s", thawed.elapsed().as_secs_f64());
    let after_hang = cell.run(u32::from(SLOT), None).await.expect("run after the hang");
    let seen = until(&cell, Duration::from_secs(10), |s| s.state == CellState::Done).await;
    assert_eq!(seen.last().unwrap().last_run, Some(after_hang.run));

    // The last handle dropped: the owner ends and releases the controller (it owned it: it ran
    // plans), so another client owns it at once rather than after the lease.
    let end = cell.owner_end();
    drop(cell);
    assert!(end.wait(Duration::from_secs(4)), "the owner thread did not end");
    let mut next = emu.connect("cell_owner next owner").expect("connect after the cell");
    next.clear_fault().expect("the ended owner released the controller");
}
