//! The sense task: keeps the accelerometer set up and hands its samples to the drive.
//!
//! Each time INT1 says the FIFO reached its threshold, the Z samples are read and sent to the
//! drive task with the drive's sample clock at the read ([`DriveShared::push_batch`]): the
//! drive turns that stamp into each sample's time for the lock-in. Errors go to the drive too
//! ([`DriveShared::push_sensor_error`]), which decides whether they are a fault (they are while
//! driving), and the sensor is set up again after a pause. Silence (INT1 never rising) is not
//! an error here: the drive's no-data monitor times it.
//!
//! Rate: 3.33 kHz. The FIFO holds X, Y and Z, so reading it at 6.66 kHz would take about 90 %
//! of the 400 kHz bus; 3.33 kHz takes about 45 % and still gives 18 samples per cycle at
//! 180 Hz. Drives above the sensor's Nyquist frequency alias, which the lock-in handles (it
//! evaluates its reference at each sample's time).

use core::future::Future;

use embassy_time::{Duration, Instant, Timer, with_timeout};
use embedded_hal_async::i2c::I2c;

use crate::app::drive::{DriveShared, SENSOR_BATCH};
use crate::app::sense::lsm6dsl::{Config, Lsm6dsl, Odr, Range};
use crate::app::watchdog::{Supervisor, Task};

/// The accelerometer's set-up: ±16 g (the plate reaches ~20 g at resonance at full drive),
/// 3.33 kHz, INT1 every 16 samples (4.8 ms, about one drive block).
pub const CONFIG: Config = Config { range: Range::G16, odr: Odr::Hz3330, fifo_threshold: 16 };

/// How long to wait for INT1 before looking again (and checking in with the watchdog).
const WAIT: Duration = Duration::from_millis(20);
/// How often the sensor's identity is read again while it runs.
const ID_CHECK: Duration = Duration::from_millis(100);
/// Pause before setting the sensor up again after an error.
const RETRY: Duration = Duration::from_millis(50);

/// The sensor's INT1 line, as each board provides it.
pub trait DataReady {
    /// Waits until the FIFO holds at least its threshold.
    fn wait(&mut self) -> impl Future<Output = ()>;
}

/// Runs the accelerometer for ever: set up, read on INT1, report errors, set up again.
pub async fn run<B: I2c, R: DataReady>(
    drive: &DriveShared,
    supervisor: &Supervisor,
    bus: B,
    irq: &mut R,
) -> ! {
    let mut sensor = Lsm6dsl::new(bus);
    drive.set_sensor_scale(CONFIG.range.sensitivity(), CONFIG.odr.millihertz());
    loop {
        supervisor.check_in(Task::Sense);
        if let Err(e) = sensor.init(CONFIG).await {
            defmt::warn!("sense: set-up failed: {}", e.name());
            drive.push_sensor_error(e.fault());
            Timer::after(RETRY).await;
            continue;
        }
        defmt::info!("sense: LSM6DSL at {=u32} mHz, ±16 g", CONFIG.odr.millihertz());
        let e = read_until_error(drive, supervisor, &mut sensor, irq).await;
        defmt::warn!("sense: {}", e.name());
        drive.push_sensor_error(e.fault());
        Timer::after(RETRY).await;
    }
}

/// Reads batches until the sensor fails; returns the failure.
async fn read_until_error<B: I2c, R: DataReady>(
    drive: &DriveShared,
    supervisor: &Supervisor,
    sensor: &mut Lsm6dsl<B>,
    irq: &mut R,
) -> crate::app::sense::lsm6dsl::SensorError {
    let mut buf = [0i16; SENSOR_BATCH];
    let mut id_checked = Instant::now();
    loop {
        supervisor.check_in(Task::Sense);
        let ready = with_timeout(WAIT, irq.wait()).await.is_ok();
        if ready {
            match sensor.read_z(&mut buf).await {
                Ok(n) => drive.push_batch(&buf[..n]),
                Err(e) => return e,
            }
        }
        if id_checked.elapsed() >= ID_CHECK {
            id_checked = Instant::now();
            if let Err(e) = sensor.check_id().await {
                return e;
            }
        }
    }
}
