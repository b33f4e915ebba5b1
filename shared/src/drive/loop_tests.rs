//! The closed loop against the simulated rig, block by block as the firmware runs it:
//! DDS → plant → simulated accelerometer → FIFO read with jitter → [`ClosedLoop`] → effort.
//! The figures printed here (`cargo test -p chladni-shared loop_tests -- --nocapture --test-threads 1`)
//! are the ones quoted in docs/control.md.

extern crate std;

use crate::drive::closed_loop::{BlockInput, ClosedLoop, LoopOutput, Stage};
use crate::drive::dds::{Dds, SAMPLES_PER_MS, gain_of_q15, tuning_word};
use crate::drive::lockin::LSB_16G_MPS2;
use crate::drive::plant::{Plant, PlantFault, PlantParams};
use crate::drive::runner::BLOCK_LEN;
use crate::drive::sensor_sim::{SensorSim, SensorSimConfig};
use crate::drive::timeline::PhaseMark;
use crate::icd::sense::{ControlConfig, FaultCause, SensorFault};
use std::vec::Vec;

/// The simulated rig and the firmware's per-block loop.
struct Rig {
    plant: Plant,
    sensor: SensorSim,
    dds: Dds,
    gain: i32,
    /// DAC samples output so far.
    now: u64,
    /// Sensor samples taken but not yet read: (value, DAC sample when taken).
    fifo: Vec<(i16, u64)>,
    lp: ClosedLoop,
    rng: u64,
    /// Read delay after the block boundary, at most this fraction of a block.
    jitter: f64,
    /// Harmonics added to the plate's acceleration: (2nd, 3rd) amplitude, m/s².
    harmonics: (f32, f32),
    silent: bool,
    peak_response: u32,
    /// The block being output, its DDS phases, and how far it is.
    pending: [u16; BLOCK_LEN],
    pending_phase: [u32; BLOCK_LEN],
    pos: usize,
    /// The phase mark of the block filled last (published by the runner when filling it).
    mark_of_filled: PhaseMark,
    /// The effort of the block filled last.
    effort: u16,
    ceiling: u16,
}

impl Rig {
    fn new(freq_mhz: u32, sensor: SensorSimConfig, cfg: ControlConfig) -> Self {
        Self {
            plant: Plant::new(PlantParams::DEFAULT),
            sensor: SensorSim::new(sensor),
            dds: Dds::new(tuning_word(freq_mhz)),
            gain: 0,
            now: 0,
            fifo: Vec::new(),
            lp: ClosedLoop::new(cfg, sensor.odr_mhz, sensor.lsb_mps2),
            rng: 0x9e37_79b9_7f4a_7c15,
            pending: [crate::drive::dds::DAC_MID; BLOCK_LEN],
            pending_phase: [0; BLOCK_LEN],
            pos: 0,
            mark_of_filled: PhaseMark { sample: 0, phase: 0, tuning_word: tuning_word(freq_mhz) },
            effort: 0,
            ceiling: 32767,
            jitter: 0.3,
            harmonics: (0.0, 0.0),
            silent: false,
            peak_response: 0,
        }
    }

    fn random(&mut self) -> f64 {
        self.rng ^= self.rng << 13;
        self.rng ^= self.rng >> 7;
        self.rng ^= self.rng << 17;
        (self.rng >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Runs `n` samples of the block being output through the plant and the sensor.
    fn output(&mut self, n: usize) {
        for _ in 0..n {
            let c = self.pending[self.pos];
            let phase = self.pending_phase[self.pos];
            self.pos += 1;
            let mut a = self.plant.step(c);
            let (h2, h3) = self.harmonics;
            if h2 != 0.0 || h3 != 0.0 {
                let phi = phase as f64 / 4_294_967_296.0 * core::f64::consts::TAU;
                a += h2 * (2.0 * phi + 0.3).sin() as f32 + h3 * (3.0 * phi + 1.1).sin() as f32;
            }
            let at = self.now;
            let fifo = &mut self.fifo;
            self.sensor.push(a, |x| fifo.push((x, at)));
            self.now += 1;
        }
    }

    /// One block as the firmware runs it: while the DMA outputs the block filled last time,
    /// the drive task wakes (up to `jitter` blocks late), reads the FIFO, updates the loop,
    /// and fills the next block ramping to the effort asked for (`open_effort` in open loop).
    fn block(&mut self, open_effort: u16, target: Option<u32>, ramp_ms: u32) -> LoopOutput {
        let delay = (self.random() * self.jitter * BLOCK_LEN as f64) as usize;
        self.output(delay);
        let batch: Vec<i16> = self.fifo.drain(..).map(|(x, _)| x).collect();
        if !self.silent {
            self.lp.push_batch(&batch, self.now);
        }
        let input = BlockInput {
            now_sample: self.now,
            mark: self.mark_of_filled,
            target_mmps2: target,
            ramp_ms,
            effort_ceiling_q15: self.ceiling,
            driving: true,
            open_effort_q15: open_effort,
        };
        let out = self.lp.update(&input);
        if let Some(m) = out.measurement {
            self.peak_response = self.peak_response.max(m.accel_mmps2);
        }
        self.output(BLOCK_LEN - delay);
        // Fill the next block.
        let effort = out.effort_q15.unwrap_or(open_effort);
        self.effort = effort;
        let new_gain = gain_of_q15(effort);
        let mut g = self.gain;
        self.mark_of_filled = PhaseMark {
            sample: self.now,
            phase: self.dds.phase,
            tuning_word: self.dds.tuning_word,
        };
        for k in 0..BLOCK_LEN {
            self.pending_phase[k] =
                self.dds.phase.wrapping_add(self.dds.tuning_word.wrapping_mul(k as u32));
        }
        self.dds.fill_ramp(&mut self.pending, &mut g, (new_gain - self.gain) / BLOCK_LEN as i32);
        self.gain = new_gain;
        self.pos = 0;
        out
    }

    /// Changes the drive frequency from the next block filled (phase kept).
    fn set_freq(&mut self, freq_mhz: u32) {
        self.dds.tuning_word = tuning_word(freq_mhz);
    }
}

fn quiet_sensor() -> SensorSimConfig {
    SensorSimConfig { noise_lsb: 4.0, ..SensorSimConfig::DEFAULT }
}

struct Settle {
    check_blocks: usize,
    settle_samples: Option<u64>,
    worst_after: f64,
    peak: u32,
}

/// A closed-loop run from rest to `target`; settling counted from the end of the loop check
/// (the start of the setpoint ramp) to the first measurement after which every measurement
/// stays within 2 %.
fn settle(freq_mhz: u32, target: u32, ramp_ms: u32, blocks: usize) -> Settle {
    let mut rig = Rig::new(freq_mhz, quiet_sensor(), ControlConfig::DEFAULT);
    let mut ramp_start = None;
    let mut last_outside = 0u64;
    let mut worst_after = 0f64;
    let mut check_blocks = 0;
    let mut trace = Vec::new();
    for b in 0..blocks {
        let out = rig.block(0, Some(target), ramp_ms);
        assert_eq!(out.fault, None, "{freq_mhz} mHz block {b}: {:?}", out.fault);
        let effort = out.effort_q15.expect("closed loop");
        if ramp_start.is_none() && rig.lp.stage() == Stage::Run {
            ramp_start = Some(rig.now);
            check_blocks = b + 1;
        }
        if let (Some(m), Some(_)) = (out.measurement, ramp_start) {
            let err = (m.accel_mmps2 as f64 / target as f64 - 1.0).abs();
            trace.push((rig.now, m.accel_mmps2, effort));
            if err > 0.02 {
                last_outside = rig.now;
            }
            if b > blocks / 2 {
                worst_after = worst_after.max(err);
            }
        }
    }
    let start = ramp_start.expect("loop check passed");
    if std::env::var("CHLADNI_TRACE").is_ok() {
        std::println!("{trace:?}");
    }
    Settle {
        check_blocks,
        settle_samples: (last_outside < rig.now - 20 * BLOCK_LEN as u64)
            .then(|| last_outside.saturating_sub(start)),
        worst_after,
        peak: rig.peak_response,
    }
}

#[test]
fn settles_below_at_and_above_resonance() {
    let cfg = ControlConfig::DEFAULT;
    for (f, target) in [(60_000u32, 1_500u32), (180_000, 100_000), (600_000, 10_000)] {
        let ramp_ms = 10;
        let s = settle(f, target, ramp_ms, 200);
        let period_samples = 50_000_000.0 / f as f64;
        let samples = s.settle_samples.expect("settles");
        let cycles = samples as f64 / period_samples;
        std::println!(
            "settle {:>5.0} Hz to {:>6} mm/s² (ramp {ramp_ms} ms, check {} blocks): {:5.1} \
             cycles = {:5.1} ms from the ramp's start; peak {} mm/s², worst error in 2nd half \
             {:.2} %",
            f as f64 / 1000.0,
            target,
            s.check_blocks,
            cycles,
            samples as f64 / SAMPLES_PER_MS as f64,
            s.peak,
            s.worst_after * 100.0
        );
        assert!(cycles <= 20.0, "{f} mHz: {cycles} cycles");
        assert!(s.peak < cfg.max_accel_mmps2, "{f} mHz: peak {}", s.peak);
        assert!(s.worst_after < 0.02);
    }
}
