//! `chladni rig`: a virtual rig (docs/rig.md). A snapshot camera over a simulated plate whose
//! parts move by the motion model under whatever the controller at `--port` drives (followed as
//! a second client), on a true plate that differs from the plate file given. It prints one line
//! once it listens (`--json`: [`chladni_rig::ListeningJson`]) and serves until Ctrl-C (exit 0)
//! or until the controller's link is lost (exit 1, named).

use std::io::Write as _;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use chladni_core::model::plate_file::PlateFile;
use chladni_core::model::pose::Pose;
use chladni_core::output::write_atomic;
use chladni_core::rng::Rng;
use chladni_rig::serve::MAX_PICK_TIME_S;
use chladni_rig::{
    DEFAULT_NOISE, DEFAULT_PICK_TIME, DEFAULT_WARP, Fail, FailMode, ListeningJson, Noise, Rig,
    RigConfig, RigError, ServeOptions, TruePlate, TruePlateJson, Warp,
};
use clap::{Args, ValueEnum};

use super::part::PartRead;
use super::{InputError, check_output, output_error};

/// Arguments of `chladni rig`.
#[derive(Debug, Args)]
pub struct RigArgs {
    /// The controller's link to follow: a serial device or tcp://HOST:PORT (the emulator).
    #[arg(long)]
    port: String,
    /// The plate as the user knows it (TOML): the true plate differs from it.
    #[arg(long, value_name = "GIVEN.toml")]
    plate: PathBuf,
    /// A part kind on the plate (JSON, SVG or DXF); repeat for several.
    #[arg(long = "part", value_name = "FILE", required = true)]
    parts: Vec<PathBuf>,
    #[command(flatten)]
    read: PartRead,
    /// Copies of each part on the plate.
    #[arg(long, value_name = "N", default_value_t = 1,
          value_parser = clap::value_parser!(u16).range(1..=100))]
    count: u16,
    /// The true plate as a plate file of its own (same size as --plate), instead of a warp.
    #[arg(long, value_name = "TRUE.toml", conflicts_with_all = ["warp_mm", "speed_factor"])]
    true_plate: Option<PathBuf>,
    /// How far each mode's nodes lie from the given plate's, drawn in MIN..MAX mm (or one
    /// value), in a random direction [default: 4..8].
    #[arg(long, value_name = "MIN..MAX", value_parser = range("warp-mm"))]
    warp_mm: Option<[f64; 2]>,
    /// Each mode's true speed over the given plate's, drawn log-uniformly in MIN..MAX (or one
    /// value) [default: 0.4..2.5].
    #[arg(long, value_name = "MIN..MAX", value_parser = range("speed-factor"))]
    speed_factor: Option<[f64; 2]>,
    /// Seed of the warp, the drops, the noise and the frames.
    #[arg(long, value_name = "S", default_value_t = 1)]
    seed: u64,
    /// Bouncing noise in position while the drive is on: mm per √s on each axis.
    #[arg(long, value_name = "S", default_value_t = DEFAULT_NOISE.mm,
          value_parser = super::parse::non_negative("noise-mm"))]
    noise_mm: f64,
    /// Bouncing noise in orientation while the drive is on: degrees per √s.
    #[arg(long, value_name = "S", default_value_t = DEFAULT_NOISE.deg,
          value_parser = super::parse::non_negative("noise-deg"))]
    noise_deg: f64,
    /// A part's start pose X,Y,THETA (mm, mm, degrees); one per part on the plate, in the order
    /// of --part with each part's copies together (default: random drops).
    #[arg(long, value_name = "X,Y,THETA", value_parser = pose, allow_negative_numbers = true)]
    at: Vec<Pose>,
    /// Where the camera listens (port 0: a free port, printed).
    #[arg(long, value_name = "ADDR:PORT", default_value = "127.0.0.1:0")]
    listen: SocketAddr,
    /// Write the true plate here (a plate file, to compare what is learned with it).
    #[arg(long, value_name = "F.toml")]
    write_true_plate: Option<PathBuf>,
    /// Answer this many frames, then fail as --fail-mode says (tests of broken cameras).
    #[arg(long, value_name = "N", requires = "fail_mode")]
    fail_after_frames: Option<u64>,
    /// How the camera fails after --fail-after-frames frames.
    #[arg(long, value_enum, requires = "fail_after_frames")]
    fail_mode: Option<FailArg>,
    /// The robot's pick time (s): a part leaves the plate this long after `POST /pick`
    /// (0 to 600).
    #[arg(long, value_name = "S", default_value_t = DEFAULT_PICK_TIME.as_secs_f64(),
          value_parser = pick_time)]
    pick_time_s: f64,
    /// Print the listening line as JSON.
    #[arg(long)]
    json: bool,
}

/// `--pick-time-s`: finite, 0 to [`MAX_PICK_TIME_S`] s.
fn pick_time(s: &str) -> Result<f64, String> {
    s.trim()
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite() && (0.0..=MAX_PICK_TIME_S).contains(v))
        .ok_or_else(|| {
            format!("--pick-time-s must be seconds from 0 to {MAX_PICK_TIME_S}, e.g. 2, got {s}")
        })
}

/// `--fail-mode`.
#[derive(Debug, Clone, Copy, ValueEnum)]
enum FailArg {
    /// Accept the request, never answer.
    Hang,
    /// Answer 200 with bytes that are no image.
    Garbage,
    /// Answer the last frame's bytes again, every time.
    Frozen,
    /// Answer 500.
    Status500,
}

/// `MIN..MAX` or one number: finite numbers.
fn range(name: &'static str) -> impl Fn(&str) -> Result<[f64; 2], String> + Clone + Send + Sync {
    move |s: &str| {
        let number = |v: &str| v.trim().parse::<f64>().ok().filter(|v| v.is_finite());
        let parsed = match s.split_once("..") {
            Some((a, b)) => number(a).zip(number(b)).map(|(a, b)| [a, b]),
            None => number(s).map(|v| [v, v]),
        };
        parsed
            .ok_or_else(|| format!("--{name} must be MIN..MAX (or one number), e.g. 4..8, got {s}"))
    }
}

/// `X,Y,THETA`: mm, mm, degrees.
fn pose(s: &str) -> Result<Pose, String> {
    let number = |v: &str| v.trim().parse::<f64>().ok().filter(|v| v.is_finite());
    let v: Option<Vec<f64>> = s.split(',').map(number).collect();
    match v.as_deref() {
        Some(&[x, y, theta]) => Ok(Pose { x, y, theta: theta.to_radians() }),
        _ => Err(format!("--at must be X,Y,THETA (mm, mm, degrees), e.g. 80,60,30, got {s}")),
    }
}

/// A rig error: the user's input is exit 2.
fn rig_error(e: RigError) -> anyhow::Error {
    if e.is_bad_input() { InputError(e.to_string()).into() } else { e.into() }
}

impl RigArgs {
    pub fn run(&self) -> anyhow::Result<ExitCode> {
        let mut inputs = vec![("plate", self.plate.as_path())];
        inputs.extend(self.true_plate.iter().map(|p| ("true plate", p.as_path())));
        inputs.extend(self.parts.iter().map(|p| ("part", p.as_path())));
        if let Some(out) = &self.write_true_plate {
            check_output("--write-true-plate", out, &inputs)?;
        }
        let load = |path: &PathBuf| {
            PlateFile::load(path).map_err(|e| InputError(format!("{}: {e}", path.display())))
        };
        let given = load(&self.plate)?;
        let kinds =
            self.parts.iter().map(|p| self.read.load(p)).collect::<anyhow::Result<Vec<_>>>()?;
        let mut seeds = Rng::seeded(self.seed);
        let (warp_seed, rig_seed, frame_seed) =
            (seeds.next_u64(), seeds.next_u64(), seeds.next_u64());
        let plate = match &self.true_plate {
            Some(path) => TruePlate::from_file(load(path)?, &given),
            None => {
                let warp = Warp {
                    shift_mm: self.warp_mm.unwrap_or(DEFAULT_WARP.shift_mm),
                    speed_factor: self.speed_factor.unwrap_or(DEFAULT_WARP.speed_factor),
                };
                TruePlate::warped(&given, &warp, warp_seed)
            }
        }
        .map_err(rig_error)?;
        if let Some(out) = &self.write_true_plate {
            let text = plate.to_toml().map_err(rig_error)?;
            write_atomic(out, text.as_bytes()).map_err(output_error)?;
        }
        let modes = plate.modes.clone();
        let count = usize::from(self.count);
        let parts: Vec<usize> =
            (0..kinds.len()).flat_map(|k| std::iter::repeat_n(k, count)).collect();
        let n = parts.len();
        let at = (!self.at.is_empty()).then(|| self.at.clone());
        let noise = Noise { mm: self.noise_mm, deg: self.noise_deg };
        let rig = Rig::new(RigConfig { plate, kinds, parts, at, seed: rig_seed, noise })
            .map_err(rig_error)?;
        let fail = self.fail_mode.zip(self.fail_after_frames).map(|(mode, after_frames)| Fail {
            after_frames,
            mode: match mode {
                FailArg::Hang => FailMode::Hang,
                FailArg::Garbage => FailMode::Garbage,
                FailArg::Frozen => FailMode::Frozen,
                FailArg::Status500 => FailMode::Status500,
            },
        });
        let options = ServeOptions {
            port: self.port.clone(),
            listen: self.listen,
            fail,
            seed: frame_seed,
            pick_time: Duration::from_secs_f64(self.pick_time_s),
        };
        let (stop_tx, stop_rx) = tokio::sync::mpsc::unbounded_channel();
        ctrlc::set_handler(move || {
            let _ = stop_tx.send(());
        })?;
        let true_plate = TruePlateJson {
            modes,
            source: if self.true_plate.is_some() { "file" } else { "warp" },
            written: self.write_true_plate.as_ref().map(|p| p.display().to_string()),
        };
        let announce = |addr: SocketAddr| {
            let listening = ListeningJson { parts: n, true_plate, url: frame_url(addr) };
            announce(&listening, self.json)
        };
        chladni_rig::serve(rig, &options, announce, stop_rx).map_err(rig_error)?;
        eprintln!("chladni rig: stopped");
        Ok(ExitCode::SUCCESS)
    }
}

/// The frame's URL: a camera on every interface is reached here on loopback.
fn frame_url(addr: SocketAddr) -> String {
    let shown = if addr.ip().is_unspecified() {
        SocketAddr::new(std::net::Ipv4Addr::LOCALHOST.into(), addr.port())
    } else {
        addr
    };
    format!("http://{shown}/frame.png")
}

/// Prints the listening line and flushes: a script waits for it.
fn announce(listening: &ListeningJson, json: bool) -> std::io::Result<()> {
    let mut out = std::io::stdout().lock();
    if json {
        writeln!(out, "{}", serde_json::to_string(listening).map_err(std::io::Error::other)?)?;
    } else {
        let p = &listening.true_plate;
        let how = if p.source == "file" { "from its file" } else { "warped from the given" };
        writeln!(
            out,
            "rig camera on {} ({} parts; true plate of {} modes {how}; GET /truth for the true \
             poses)",
            listening.url,
            listening.parts,
            p.modes.len()
        )?;
    }
    out.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_and_poses_parse_and_bad_ones_are_named() {
        let r = range("warp-mm");
        assert_eq!(r("4..8"), Ok([4.0, 8.0]));
        assert_eq!(r(" 0.4 .. 2.5"), Ok([0.4, 2.5]));
        assert_eq!(r("3"), Ok([3.0, 3.0]));
        assert!(r("4-8").unwrap_err().starts_with("--warp-mm must be MIN..MAX"));
        assert!(r("..8").is_err() && r("inf..8").is_err());
        let p = pose("80,-60,90").unwrap();
        assert_eq!((p.x, p.y), (80.0, -60.0));
        assert!((p.theta - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!(pose("80,60").unwrap_err().contains("X,Y,THETA"));
        assert!(pose("80,60,x").is_err() && pose("1,2,3,4").is_err());
    }
}
