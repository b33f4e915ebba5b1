//! The sense task: keeps the accelerometer set up and hands its samples to the drive.
//!
//! Each time INT1 says the FIFO reached its threshold, the Z samples are read and sent to the
//! drive task with the drive's sample clock at the read ([`DriveShared::push_batch`]): the
//! drive turns that stamp into each sample's time for the lock-in. Errors go to the drive too
//! ([`DriveShared::push_sensor_error`]), which decides whether they are a fault (they are while
//! driving), and the sensor is set up again after a pause. Silence (INT1 never rising) is not
//! an error here: the drive's no-data monitor times it.
//!
//! **A hung bus cannot stop the task.** Every operation on the sensor is bounded by
//! [`OP_LIMIT`]: one that has not finished by then is dropped (the board's I2C driver stops
//! its DMA and interrupts on drop) and reported as [`SensorError::Timeout`], and the sensor is
//! set up again after [`RETRY`]. So the task checks in with the watchdog at least every
//! `WAIT + 2 × OP_LIMIT` (120 ms), whatever the bus does, below the watchdog's 250 ms period.
//! The board's I2C driver has a timeout of its own per transfer (shorter, so it normally
//! answers first); this one also covers a driver that never returns.
//!
//! Rate: 3.33 kHz. The FIFO holds X, Y and Z, so reading it at 6.66 kHz would take about 90 %
//! of the 400 kHz bus; 3.33 kHz takes about 45 % and still gives 18 samples per cycle at
//! 180 Hz. Drives above the sensor's Nyquist frequency alias, which the lock-in handles (it
//! evaluates its reference at each sample's time).

use core::future::Future;

use chladni_shared::icd::sense::SensorFault;
use embassy_time::{Duration, Instant, Timer, with_timeout};
use embedded_hal_async::i2c::I2c;

use crate::app::drive::{DriveShared, SENSOR_BATCH};
use crate::app::sense::lsm6dsl::{Config, Lsm6dsl, Odr, Range, SensorError};
use crate::app::watchdog::{Supervisor, Task};

/// The accelerometer's set-up: ±16 g (the plate reaches ~20 g at resonance at full drive),
/// 3.33 kHz, INT1 every 16 samples (4.8 ms, about one drive block).
pub const CONFIG: Config = Config { range: Range::G16, odr: Odr::Hz3330, fifo_threshold: 16 };

/// How long to wait for INT1 before looking again (and checking in with the watchdog).
const WAIT: Duration = Duration::from_millis(20);
/// How often the sensor's identity is read again while it runs.
const ID_CHECK: Duration = Duration::from_millis(100);
/// Pause before setting the sensor up again after an error.
pub const RETRY: Duration = Duration::from_millis(50);
/// The longest one operation on the sensor may take: set-up (7 transfers and up to 100 reset
/// polls, about 7 ms at 400 kHz), a FIFO read (a status read and a burst of at most 64 sets,
/// about 10 ms) or an identity check. Five times the longest, far below the watchdog's period.
pub const OP_LIMIT: Duration = Duration::from_millis(50);

/// Where the task's results go: the drive ([`DriveShared`]); a recorder in the tests.
pub trait SenseSink {
    /// The sensor's scale and rate, once at start.
    fn set_scale(&self, lsb_mps2: f32, odr_mhz: u32);
    /// Z samples read now.
    fn push_batch(&self, samples: &[i16]);
    /// A sensor failure.
    fn push_error(&self, fault: SensorFault);
}

impl SenseSink for DriveShared {
    fn set_scale(&self, lsb_mps2: f32, odr_mhz: u32) {
        self.set_sensor_scale(lsb_mps2, odr_mhz);
    }

    fn push_batch(&self, samples: &[i16]) {
        DriveShared::push_batch(self, samples);
    }

    fn push_error(&self, fault: SensorFault) {
        self.push_sensor_error(fault);
    }
}

/// Runs one operation on the sensor, bounded by [`OP_LIMIT`].
async fn bounded<T>(op: impl Future<Output = Result<T, SensorError>>) -> Result<T, SensorError> {
    with_timeout(OP_LIMIT, op).await.unwrap_or(Err(SensorError::Timeout))
}

/// The sensor's INT1 line, as each board provides it.
pub trait DataReady {
    /// Waits until the FIFO holds at least its threshold.
    fn wait(&mut self) -> impl Future<Output = ()>;
}

/// Runs the accelerometer for ever: set up, read on INT1, report errors, set up again.
pub async fn run<B: I2c, R: DataReady>(
    drive: &impl SenseSink,
    supervisor: &Supervisor,
    bus: B,
    irq: &mut R,
) -> ! {
    let mut sensor = Lsm6dsl::new(bus);
    drive.set_scale(CONFIG.range.sensitivity(), CONFIG.odr.millihertz());
    loop {
        supervisor.check_in(Task::Sense);
        if let Err(e) = bounded(sensor.init(CONFIG)).await {
            defmt::warn!("sense: set-up failed: {}", e.name());
            drive.push_error(e.fault());
            Timer::after(RETRY).await;
            continue;
        }
        defmt::info!("sense: LSM6DSL at {=u32} mHz, ±16 g", CONFIG.odr.millihertz());
        let e = read_until_error(drive, supervisor, &mut sensor, irq).await;
        defmt::warn!("sense: {}", e.name());
        drive.push_error(e.fault());
        Timer::after(RETRY).await;
    }
}

/// Reads batches until the sensor fails; returns the failure.
async fn read_until_error<B: I2c, R: DataReady>(
    drive: &impl SenseSink,
    supervisor: &Supervisor,
    sensor: &mut Lsm6dsl<B>,
    irq: &mut R,
) -> SensorError {
    let mut buf = [0i16; SENSOR_BATCH];
    let mut id_checked = Instant::now();
    loop {
        supervisor.check_in(Task::Sense);
        let ready = with_timeout(WAIT, irq.wait()).await.is_ok();
        if ready {
            match bounded(sensor.read_z(&mut buf)).await {
                Ok(n) => drive.push_batch(&buf[..n]),
                Err(e) => return e,
            }
        }
        if id_checked.elapsed() >= ID_CHECK {
            id_checked = Instant::now();
            if let Err(e) = bounded(sensor.check_id()).await {
                return e;
            }
        }
    }
}
