//! The watchdog's check-in rule, board-independent: the hardware watchdog is fed only while
//! every task of the firmware shows it is still making progress.
//!
//! Each concern runs in its own task (link, drive, later sense). A hardware watchdog petted
//! from a timer alone would only prove that the executor still runs; a task stuck in a loop
//! that awaits (a link waiting forever on a dead peer state, a drive that stopped refilling)
//! would go unnoticed. So each task calls [`Supervisor::check_in`] as it makes progress, and
//! [`watchdog_task`] pets the dog every period only if [`Supervisor::poll`] says every
//! registered task checked in since the last pet. A task that stops checking in stops the
//! feeding; the board's watchdog then resets the controller, which comes up idle with the
//! drive at zero and reports [`ResetCause::Watchdog`].
//!
//! The rule for the timeout (docs/firmware.md, "Watchdog"): each task checks in at least once
//! per poll period, so a pet happens at least every two periods; the board's shortest timeout
//! (its clock's worst case) must exceed that with margin.

use core::cell::Cell;

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_time::{Duration, Instant, Ticker};

/// A supervised task: one bit of a [`TaskSet`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
#[repr(u8)]
pub enum Task {
    /// The host link (requests, telemetry).
    Link = 0b001,
    /// The drive (sample blocks into the output).
    Drive = 0b010,
    /// The sensing (to come).
    Sense = 0b100,
}

/// A set of [`Task`]s as a bitmask.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, defmt::Format)]
pub struct TaskSet(u8);

impl TaskSet {
    /// No task.
    pub const EMPTY: TaskSet = TaskSet(0);

    /// The set of `tasks`.
    pub const fn of(tasks: &[Task]) -> TaskSet {
        let mut bits = 0;
        let mut i = 0;
        while i < tasks.len() {
            bits |= tasks[i] as u8;
            i += 1;
        }
        TaskSet(bits)
    }

    /// Whether `task` is in the set.
    pub const fn contains(self, task: Task) -> bool {
        self.0 & task as u8 != 0
    }

    /// The set as a bitmask (bit 0 link, bit 1 drive, bit 2 sense).
    pub const fn bits(self) -> u8 {
        self.0
    }
}

impl Task {
    /// The task's place in per-task tables (its bit's position).
    const fn slot(self) -> usize {
        (self as u8).trailing_zeros() as usize
    }
}

/// Told that work done on behalf of a task made progress: a long operation inside a task (the
/// store's flash work inside the link task) reports each step, so the task checks in while it
/// works rather than only between requests.
pub trait Progress: Sync {
    /// `task` made progress.
    fn progress(&self, task: Task);
}

impl Progress for Supervisor {
    fn progress(&self, task: Task) {
        self.check_in(task);
    }
}

/// When each task last checked in and the longest gap between two of its check-ins, µs.
#[derive(Debug, Clone, Copy)]
struct Gaps {
    last: [Option<u64>; 3],
    longest: [u64; 3],
}

/// Who must check in before the dog is fed, and who has since the last feed.
///
/// Shared by every task through a `&'static` (a `static SUPERVISOR: Supervisor = ...`): the
/// marks sit behind a critical-section mutex, so [`Supervisor::check_in`] may be called from
/// any task or interrupt. It also measures the longest gap between two check-ins of each task
/// ([`Supervisor::longest_gap`]): the margin the watchdog's timeout has in practice.
pub struct Supervisor {
    registered: TaskSet,
    marks: Mutex<CriticalSectionRawMutex, Cell<u8>>,
    gaps: Mutex<CriticalSectionRawMutex, Cell<Gaps>>,
}

impl Supervisor {
    /// A supervisor of the `registered` tasks, none checked in yet.
    pub const fn new(registered: TaskSet) -> Self {
        let gaps = Gaps { last: [None; 3], longest: [0; 3] };
        Self { registered, marks: Mutex::new(Cell::new(0)), gaps: Mutex::new(Cell::new(gaps)) }
    }

    /// The longest time between two check-ins of `task` since boot (zero before its second).
    pub fn longest_gap(&self, task: Task) -> Duration {
        Duration::from_micros(self.gaps.lock(Cell::get).longest[task.slot()])
    }

    /// Notes a check-in of `task` at `now` for the gap measurement.
    fn note_gap(&self, task: Task, now: Instant) {
        let now = now.as_micros();
        self.gaps.lock(|g| {
            let mut gaps = g.get();
            let i = task.slot();
            if let Some(last) = gaps.last[i] {
                gaps.longest[i] = gaps.longest[i].max(now.saturating_sub(last));
            }
            gaps.last[i] = Some(now);
            g.set(gaps);
        });
    }

    /// The tasks that must check in.
    pub fn registered(&self) -> TaskSet {
        self.registered
    }

    /// `task` made progress. A task that is not registered is ignored.
    pub fn check_in(&self, task: Task) {
        let bit = task as u8 & self.registered.0;
        self.marks.lock(|m| m.set(m.get() | bit));
        if bit != 0 {
            self.note_gap(task, Instant::now());
        }
    }

    /// Whether to feed the dog now: true only if every registered task checked in since the
    /// last time this returned true; then the marks start again from none. While some task
    /// is missing, the marks of the others are kept.
    pub fn poll(&self) -> bool {
        self.marks.lock(|m| {
            let all = m.get() & self.registered.0 == self.registered.0;
            if all {
                m.set(0);
            }
            all
        })
    }

    /// The registered tasks that have not checked in since the last feed (for the log).
    pub fn missing(&self) -> TaskSet {
        TaskSet(self.registered.0 & !self.marks.lock(Cell::get))
    }
}

/// A hardware (or simulated) watchdog, implemented by each board.
pub trait Watchdog {
    /// Starts the countdown; from then on it must be petted within its timeout. Called once,
    /// by [`watchdog_task`] before its first poll.
    fn start(&mut self);
    /// Restarts the countdown.
    fn pet(&mut self);
}

/// Runs the watchdog: starts `dog`, then every `period` pets it if [`Supervisor::poll`]
/// allows; otherwise logs the tasks that are missing and lets the countdown run on.
pub async fn watchdog_task(
    supervisor: &'static Supervisor,
    mut dog: impl Watchdog,
    period: Duration,
) -> ! {
    dog.start();
    let mut ticker = Ticker::every(period);
    let mut starving = false;
    let mut logged = [Duration::from_ticks(0); 3];
    loop {
        ticker.next().await;
        log_gaps(supervisor, &mut logged);
        if supervisor.poll() {
            dog.pet();
            starving = false;
        } else if !starving {
            // Once per stall: the log must not flood while the countdown runs out.
            defmt::warn!("watchdog: not fed, tasks missing {=u8:03b}", supervisor.missing().bits());
            starving = true;
        }
    }
}

/// Logs a task's longest check-in gap when it grew by more than a millisecond since last
/// logged (rarely, once the longest request has been seen): the number the tests and
/// docs/store.md read.
fn log_gaps(supervisor: &Supervisor, logged: &mut [Duration; 3]) {
    for task in [Task::Link, Task::Drive, Task::Sense] {
        let gap = supervisor.longest_gap(task);
        let seen = &mut logged[task.slot()];
        if gap.as_micros() > seen.as_micros() + 1_000 {
            *seen = gap;
            defmt::info!("watchdog: longest check-in gap of {} {=u64} us", task, gap.as_micros());
        }
    }
}

/// Why the controller last started (the wire type: the status reports it).
pub use chladni_shared::icd::sense::ResetCause;

/// The reset flags a board reads (STM32 RCC_CSR's `…RSTF` bits, or the QEMU board's record).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ResetFlags {
    /// Independent or window watchdog (IWDGRSTF, WWDGRSTF).
    pub watchdog: bool,
    /// Software reset (SFTRSTF).
    pub software: bool,
    /// Brown-out reset, which a power-on also sets (BORRSTF).
    pub brown_out: bool,
    /// The NRST pin (PINRSTF).
    pub pin: bool,
}

impl ResetFlags {
    /// The cause the flags say. Several flags are set by one reset (an internal reset also
    /// pulls NRST, so PINRSTF comes with every cause), so the most specific wins: watchdog,
    /// then software, then power-on, then the pin; none at all is `Other`.
    pub const fn cause(self) -> ResetCause {
        let flags = self;
        if flags.watchdog {
            ResetCause::Watchdog
        } else if flags.software {
            ResetCause::Software
        } else if flags.brown_out {
            ResetCause::PowerOn
        } else {
            ResetCause::Other
        }
    }
}

#[cfg(all(test, not(target_os = "none")))]
mod tests {
    use super::*;

    const ALL: TaskSet = TaskSet::of(&[Task::Link, Task::Drive, Task::Sense]);

    #[test]
    fn all_tasks_in_feeds_once_then_needs_them_all_again() {
        let s = Supervisor::new(ALL);
        assert!(!s.poll(), "nobody checked in yet");
        s.check_in(Task::Link);
        s.check_in(Task::Drive);
        assert!(!s.poll(), "sense is missing");
        assert_eq!(s.missing(), TaskSet::of(&[Task::Sense]));
        s.check_in(Task::Sense);
        assert!(s.poll(), "all three checked in (link and drive before the failed poll)");
        assert!(!s.poll(), "the marks are cleared by a feed");
        assert_eq!(s.missing(), ALL);
    }

    #[test]
    fn a_task_that_stops_checking_in_stops_the_feeding() {
        let s = Supervisor::new(ALL);
        let mut fed = [false; 10];
        for (period, fed) in fed.iter_mut().enumerate() {
            s.check_in(Task::Link);
            s.check_in(Task::Sense);
            // The drive checks in many times per period, then hangs from period 4 on.
            if period < 4 {
                for _ in 0..3 {
                    s.check_in(Task::Drive);
                }
            }
            *fed = s.poll();
        }
        assert_eq!(fed, [true, true, true, true, false, false, false, false, false, false]);
        assert_eq!(s.missing(), TaskSet::of(&[Task::Drive]));
    }

    #[test]
    fn only_registered_tasks_are_needed_and_others_are_ignored() {
        let s = Supervisor::new(TaskSet::of(&[Task::Link, Task::Drive]));
        s.check_in(Task::Sense);
        assert!(!s.poll());
        assert_eq!(s.missing(), TaskSet::of(&[Task::Link, Task::Drive]));
        s.check_in(Task::Drive);
        s.check_in(Task::Link);
        assert!(s.poll());
        // An empty set is always satisfied: the dog is fed on every poll.
        assert!(Supervisor::new(TaskSet::EMPTY).poll());
    }

    #[test]
    fn the_longest_gap_between_check_ins_is_kept_per_task() {
        let s = Supervisor::new(ALL);
        let at = |ms| Instant::from_millis(ms);
        assert_eq!(s.longest_gap(Task::Link), Duration::from_ticks(0), "none before two");
        s.note_gap(Task::Link, at(1_000));
        s.note_gap(Task::Link, at(1_100));
        s.note_gap(Task::Drive, at(1_105));
        s.note_gap(Task::Link, at(1_130));
        s.note_gap(Task::Drive, at(1_110));
        assert_eq!(s.longest_gap(Task::Link), Duration::from_millis(100));
        assert_eq!(s.longest_gap(Task::Drive), Duration::from_millis(5));
        assert_eq!(s.longest_gap(Task::Sense), Duration::from_ticks(0));
        // Progress reported for a task is its check-in.
        Progress::progress(&s, Task::Sense);
        assert_eq!(s.missing(), TaskSet::of(&[Task::Link, Task::Drive]));
    }

    #[test]
    fn the_reset_cause_takes_the_most_specific_flag() {
        let f =
            |watchdog, software, brown_out, pin| ResetFlags { watchdog, software, brown_out, pin };
        // A watchdog reset also pulls NRST (PINRSTF); a power-on sets BORRSTF and PINRSTF.
        assert_eq!(f(true, false, false, true).cause(), ResetCause::Watchdog);
        assert_eq!(f(true, true, true, true).cause(), ResetCause::Watchdog);
        assert_eq!(f(false, true, false, true).cause(), ResetCause::Software);
        assert_eq!(f(false, false, true, true).cause(), ResetCause::PowerOn);
        assert_eq!(f(false, false, false, true).cause(), ResetCause::Other);
        assert_eq!(ResetFlags::default().cause(), ResetCause::Other);
    }
}
