//! I2C bus recovery ("bus clear", I2C specification UM10204 §3.1.16), board-independent.
//!
//! A reset in the middle of a read leaves the sensor where it was: it may be driving SDA low
//! for a 0 bit and wait for clocks that no longer come. The I2C peripheral then sees a busy
//! bus and every transfer fails (or, without a timeout, waits) until the sensor is powered
//! off. The cure: before the I2C driver takes the pins, clock SCL by hand, up to nine times,
//! until the sensor has shifted its byte out and released SDA (it does by the ninth clock, the
//! acknowledge slot), then send a STOP so that every device on the bus returns to idle.
//!
//! The board supplies the two pins as open-drain lines ([`OpenDrainPins`]); the sequence is
//! here, tested on the host against a simulated device that holds SDA low.

/// SCL and SDA as open-drain lines: "high" releases the line (the pull-ups raise it unless a
/// device holds it low), "low" drives it low. Reads return the level on the wire.
pub trait OpenDrainPins {
    /// Drives SCL low (`false`) or releases it (`true`).
    fn set_scl(&mut self, high: bool);
    /// Drives SDA low (`false`) or releases it (`true`).
    fn set_sda(&mut self, high: bool);
    /// The level on SCL.
    fn scl(&self) -> bool;
    /// The level on SDA.
    fn sda(&self) -> bool;
    /// Waits half an SCL period (5 µs gives 100 kHz, the standard-mode rate every device
    /// takes).
    fn half_period(&mut self);
}

/// Clocks a device may need to release SDA: the 8 bits of a byte it is sending and the
/// acknowledge slot.
pub const MAX_CLOCKS: u8 = 9;

/// Half-periods to wait for a released SCL to rise (a device stretching the clock): 1 ms at
/// 5 µs each. Longer means SCL is held or shorted low.
pub const SCL_RISE_LIMIT: u32 = 200;

/// What the recovery did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub struct Recovered {
    /// Clocks sent before SDA was high (0: the bus was idle).
    pub clocks: u8,
}

/// Why the bus could not be freed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum BusStuck {
    /// SCL stayed low after being released (held or shorted low; missing pull-up).
    SclLow,
    /// SDA was still low after [`MAX_CLOCKS`] clocks (a device that does not let go, or SDA
    /// shorted low).
    SdaLow,
}

impl BusStuck {
    /// A short name for messages.
    pub const fn name(self) -> &'static str {
        match self {
            BusStuck::SclLow => "SCL held low",
            BusStuck::SdaLow => "SDA held low after 9 clocks",
        }
    }
}

/// Releases SCL and waits for it to rise, as a device may stretch the clock.
fn release_scl(pins: &mut impl OpenDrainPins) -> Result<(), BusStuck> {
    pins.set_scl(true);
    for _ in 0..SCL_RISE_LIMIT {
        if pins.scl() {
            return Ok(());
        }
        pins.half_period();
    }
    Err(BusStuck::SclLow)
}

/// Frees the bus: up to [`MAX_CLOCKS`] clocks on SCL while SDA is low, then a STOP (SDA rising
/// while SCL is high), sent also when the bus looked idle, since a device in the middle of a
/// write waits for clocks with SDA high. Leaves both lines released.
pub fn recover(pins: &mut impl OpenDrainPins) -> Result<Recovered, BusStuck> {
    pins.set_sda(true);
    release_scl(pins)?;
    pins.half_period();
    let mut clocks = 0;
    while !pins.sda() {
        if clocks == MAX_CLOCKS {
            return Err(BusStuck::SdaLow);
        }
        pins.set_scl(false);
        pins.half_period();
        release_scl(pins)?;
        pins.half_period();
        clocks += 1;
    }
    // STOP: SDA low while SCL is low, SCL high, then SDA high.
    pins.set_scl(false);
    pins.half_period();
    pins.set_sda(false);
    pins.half_period();
    release_scl(pins)?;
    pins.half_period();
    pins.set_sda(true);
    pins.half_period();
    if pins.sda() { Ok(Recovered { clocks }) } else { Err(BusStuck::SdaLow) }
}

#[cfg(all(test, not(target_os = "none")))]
mod tests {
    use super::*;

    /// Two open-drain lines with one device on them: it holds SDA low until it has seen
    /// `hold` falling edges of SCL (`None`: never lets go), and may hold SCL low for good.
    /// Counts the clocks it saw, STOPs and STARTs.
    struct Bus {
        scl_out: bool,
        sda_out: bool,
        hold: Option<u32>,
        scl_held: bool,
        clocks: u32,
        stops: u32,
        starts: u32,
    }

    impl Bus {
        fn new(hold: Option<u32>) -> Self {
            Bus {
                scl_out: true,
                sda_out: true,
                hold,
                scl_held: false,
                clocks: 0,
                stops: 0,
                starts: 0,
            }
        }

        fn device_sda_low(&self) -> bool {
            self.hold != Some(0)
        }
    }

    impl OpenDrainPins for Bus {
        fn set_scl(&mut self, high: bool) {
            let was = self.scl();
            self.scl_out = high;
            if was && !self.scl() {
                self.clocks += 1;
                // The device shifts its next bit out on the falling edge.
                self.hold = self.hold.map(|n| n.saturating_sub(1));
            }
        }

        fn set_sda(&mut self, high: bool) {
            let was = self.sda();
            self.sda_out = high;
            match (was, self.sda(), self.scl()) {
                (false, true, true) => self.stops += 1,
                (true, false, true) => self.starts += 1,
                _ => {}
            }
        }

        fn scl(&self) -> bool {
            self.scl_out && !self.scl_held
        }

        fn sda(&self) -> bool {
            self.sda_out && !self.device_sda_low()
        }

        fn half_period(&mut self) {}
    }

    #[test]
    fn an_idle_bus_gets_a_stop_and_no_clocks() {
        let mut bus = Bus::new(Some(0));
        assert_eq!(recover(&mut bus), Ok(Recovered { clocks: 0 }));
        assert_eq!((bus.stops, bus.starts), (1, 0));
        assert!(bus.scl() && bus.sda(), "both lines released");
    }

    #[test]
    fn a_device_holding_sda_is_clocked_until_it_lets_go_then_stopped() {
        for hold in 1..=9 {
            let mut bus = Bus::new(Some(hold));
            assert!(!bus.sda(), "the device holds SDA at first");
            assert_eq!(recover(&mut bus), Ok(Recovered { clocks: hold as u8 }), "hold {hold}");
            assert_eq!((bus.stops, bus.starts), (1, 0), "hold {hold}");
            assert!(bus.scl() && bus.sda(), "hold {hold}: both lines released");
        }
    }

    #[test]
    fn sda_held_for_good_is_refused_after_nine_clocks() {
        let mut bus = Bus::new(None);
        assert_eq!(recover(&mut bus), Err(BusStuck::SdaLow));
        assert_eq!(bus.clocks, u32::from(MAX_CLOCKS));
        assert_eq!(bus.starts, 0);
    }

    #[test]
    fn scl_held_low_is_refused_without_clocking() {
        let mut bus = Bus::new(Some(3));
        bus.scl_held = true;
        assert_eq!(recover(&mut bus), Err(BusStuck::SclLow));
        assert_eq!(bus.clocks, 0);
    }

    #[test]
    fn stuck_names_are_distinct() {
        assert_ne!(BusStuck::SclLow.name(), BusStuck::SdaLow.name());
    }
}
