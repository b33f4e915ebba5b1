//! The messages of the host ↔ controller link: requests, their responses, and the typed
//! refusals. Framing (COBS, CRC, envelope) is in [`crate::icd::frame`].
//!
//! One table ([`endpoints!`](crate::endpoints)) pairs every request with the response it gets:
//! the answer to `Request::X` is `Response::X`, or `Response::Error` (the frame could not be
//! read) or `Response::Refused` (the request was read and refused, with the reason). The table
//! also says who may send each request (its [`Access`] column). Both sides build from it: the
//! controller implements the generated [`Handler`] trait (one method per request, returning that
//! request's reply type; [`Request::answer`] makes the response, so a handler cannot answer with
//! another request's reply), and a client asks through the [`Endpoint`] types, so it never meets
//! a response of another kind. The test module `wire_pins` pins a digest of the encoding of every
//! message to [`PROTOCOL_VERSION`]: a wire change without a version bump fails it.
//!
//! Sessions: a client picks a random session number when it connects and sends it in every
//! envelope; answers carry it back, so clients sharing one byte stream (two programs on one
//! serial port, a new client reading what an old one left) each take only their own.
//! Ownership: requests whose [`Access`] column says `Owner` are taken from one
//! session at a time, the owner; another session gets [`Refusal::Busy`] naming the owner, at
//! once. `Stop` is taken from anyone (the shaker can always be stopped), and reads (`Status`,
//! `ListPlans`, `GetConfig`, `GetInfo`, `Ping`, and the one telemetry stream, `Subscribe`)
//! never need ownership.

use serde::{Deserialize, Serialize};

pub use crate::icd::frame::{
    CRC_LEN, ENCODE_BUF, Envelope, FrameError, FrameReader, LinkError, MAX_FRAME, PROTOCOL_VERSION,
    decode, encode,
};
pub use crate::icd::plan::{Level, Plan, PlanError, SetpointError};
pub use crate::icd::sense::{Fault, FaultCause, Measurement, ResetCause, SensorFault};
use crate::icd::store::{
    ConfigError, DeviceConfig, PlanName, PlanPage, PlanRef, PlanSummary, StoreError, StoreInfo,
    UploadBegin, UploadChunk, UploadError,
};

/// Longest client name a session may give in [`Request::Hello`].
pub const MAX_CLIENT_NAME: usize = 40;
/// A session loses ownership after this long without a request from it (a client that was
/// killed cannot hold the controller for ever), milliseconds.
pub const OWNER_LEASE_MS: u32 = 3_000;
/// USB vendor id of the controller's CDC-ACM interface (pid.codes, the open-source vendor id).
pub const USB_VID: u16 = 0x1209;
/// USB product id of the controller (a pid.codes test id until the product registers its own).
pub const USB_PID: u16 = 0x0001;
/// USB product string of the controller.
pub const USB_PRODUCT: &str = "Chladni feeder controller";

/// Fastest telemetry stream, samples per second.
pub const MAX_TELEMETRY_HZ: u16 = 100;

/// Who may send a request: the owner column of the [`endpoints!`](crate::endpoints) table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Access {
    /// Any session: reads, the telemetry stream, and `Stop` (the shaker can always be stopped).
    Anyone,
    /// Only the session that owns the controller (the request changes it); another session is
    /// refused with [`Refusal::Busy`].
    Owner,
}

/// A request type and the type of its answer: one line of the [`endpoints!`](crate::endpoints)
/// table.
pub trait Endpoint: Sized {
    /// What the controller answers when it carries the request out.
    type Reply;
    /// Name of the request, for messages.
    const NAME: &'static str;
    /// Who may send it.
    const ACCESS: Access;
    /// The request as sent.
    fn into_request(self) -> Request;
    /// The response carrying `reply`.
    fn respond(reply: Self::Reply) -> Response;
    /// The reply, if `response` is this request's answer; else the response back.
    // The response comes back whole so the caller can name it; no allocator to box it.
    #[allow(clippy::result_large_err)]
    fn reply(response: Response) -> Result<Self::Reply, Response>;
}

/// Declares the request and response enums, one [`Endpoint`] per line, and the [`Handler`]
/// trait the controller implements: `Variant(RequestType) => ReplyType, Access, fn method;`.
#[macro_export]
#[doc(hidden)]
macro_rules! endpoints {
    ($(
        $(#[$doc:meta])*
        $name:ident ( $req:ty ) => $reply:ty, $access:ident, fn $method:ident;
    )*) => {
        /// Requests from the host to the controller. Each is answered by the [`Response`]
        /// variant of the same name (see [`Endpoint`]).
        // An upload chunk rides inline (no allocator on the controller to box it).
        #[allow(clippy::large_enum_variant)]
        #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        pub enum Request {
            $( $(#[$doc])* $name($req), )*
        }

        /// Responses from the controller: one variant per request (its answer), then the
        /// two ways any request can fail, then the telemetry stream.
        // A plan page rides inline (no allocator on the controller to box it).
        #[allow(clippy::large_enum_variant)]
        #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        pub enum Response {
            $(
                #[doc = concat!("Answer to [`Request::", stringify!($name), "`].")]
                $name($reply),
            )*
            /// The frame could not be read (bad CRC, unknown message, another version).
            Error(LinkError),
            /// The request was read and refused; nothing was changed.
            Refused(Refusal),
            /// One telemetry sample, sent with the session and id of the [`Request::Subscribe`]
            /// that asked for it.
            Telemetry(Telemetry),
        }

        /// The controller's side of the table: one method per endpoint, each returning that
        /// endpoint's own reply or a refusal. [`Request::answer`] turns the result into the
        /// [`Response`]; it is the only place a reply becomes a response, so an implementation
        /// cannot answer one request with another's reply (it would not compile).
        // Called from one task on a single-core executor: no `Send` bound is wanted.
        #[allow(async_fn_in_trait)]
        pub trait Handler {
            /// What every method gets besides its request (the session, the time, ...).
            type Context;
            $(
                #[doc = concat!("Carries out [`Request::", stringify!($name), "`].")]
                async fn $method(
                    &mut self,
                    context: Self::Context,
                    request: $req,
                ) -> Result<$reply, Refusal>;
            )*
        }

        impl Request {
            /// Every request's name, in the table's order (= variant numbers on the wire).
            pub const NAMES: &'static [&'static str] = &[$( stringify!($name), )*];

            /// The request's name, for logs and messages.
            pub const fn name(&self) -> &'static str {
                match self { $( Request::$name(_) => stringify!($name), )* }
            }

            /// Who may send this request (the table's owner column).
            pub const fn access(&self) -> Access {
                match self { $( Request::$name(_) => Access::$access, )* }
            }

            /// Whether only the owning session may send this request (it changes the
            /// controller). `Stop` is not among them: anyone may stop the shaker.
            pub const fn needs_owner(&self) -> bool {
                matches!(self.access(), Access::Owner)
            }

            /// Whether `response` is this request's own answer kind (not an error, a refusal
            /// or telemetry): the table's pairing, for checkers.
            pub const fn is_answered_by(&self, response: &Response) -> bool {
                match (self, response) {
                    $( (Request::$name(_), Response::$name(_)) => true, )*
                    _ => false,
                }
            }

            /// Carries the request out with `handler`'s method for it: its reply as this
            /// request's response, or `Refused`.
            pub async fn answer<H: Handler>(self, handler: &mut H, context: H::Context) -> Response {
                let mut out = Response::Error(LinkError::Malformed);
                self.answer_into(handler, context, &mut out).await;
                out
            }

            /// [`Request::answer`] written into `out` (the controller keeps one response in
            /// its link state): the reply goes from the handler's future straight into `out`,
            /// with no response-sized value returned through the callers' frames.
            pub async fn answer_into<H: Handler>(
                self,
                handler: &mut H,
                context: H::Context,
                out: &mut Response,
            ) {
                match self {
                    $(
                        Request::$name(request) => {
                            *out = match handler.$method(context, request).await {
                                Ok(reply) => Response::$name(reply),
                                Err(refusal) => Response::Refused(refusal),
                            }
                        }
                    )*
                }
            }
        }

        $(
            impl Endpoint for $req {
                type Reply = $reply;
                const NAME: &'static str = stringify!($name);
                const ACCESS: Access = Access::$access;
                fn into_request(self) -> Request {
                    Request::$name(self)
                }
                fn respond(reply: $reply) -> Response {
                    Response::$name(reply)
                }
                #[allow(clippy::result_large_err)]
                fn reply(response: Response) -> Result<$reply, Response> {
                    match response {
                        Response::$name(reply) => Ok(reply),
                        other => Err(other),
                    }
                }
            }
        )*
    };
}

// Request types: one struct per request, so each names its reply type.

/// Starts a session: names the client (shown to others while it owns the controller) and
/// checks the protocol version. Answered with the device's identity.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Hello {
    /// Who is asking, e.g. `chladni device run (pid 4242)`.
    pub client: heapless::String<MAX_CLIENT_NAME>,
}

/// Liveness check; the nonce comes back.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Ping {
    /// Any value; echoed back.
    pub nonce: u32,
}

/// Asks for the device's identity.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GetInfo;

/// Gives up ownership (a client does so when it ends).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Release;

/// Manual drive: a steady sine at `freq_mhz`, ramped to `level` (a drive amplitude, or an
/// acceleration the controller holds after a loop check).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Drive {
    /// Frequency, millihertz.
    pub freq_mhz: u32,
    /// Amplitude (open loop) or acceleration target (closed loop).
    pub level: Level,
}

/// Clears a latched fault (nothing else does: not a stop, not a new run).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ClearFault;

/// Most points of one sweep.
pub const MAX_SWEEP_POINTS: u16 = 200;
/// Points per [`SweepPage`].
pub const SWEEP_PAGE: usize = 32;

/// Steps the drive over a frequency range at one level and measures the plate's response at
/// each point (lock-in amplitude and phase at the end of the point's dwell). Points are spaced
/// geometrically from `from_mhz` to `to_mhz` (both included).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Sweep {
    /// First frequency, mHz.
    pub from_mhz: u32,
    /// Last frequency, mHz (above `from_mhz`).
    pub to_mhz: u32,
    /// Number of points, 2..=[`MAX_SWEEP_POINTS`].
    pub points: u16,
    /// Drive amplitude, Q15 (open loop: a sweep measures the plate, it does not hold it).
    pub amplitude_q15: u16,
    /// Time at each point before its measurement is taken, ms (the plate settles).
    pub dwell_ms: u32,
}

/// Asks for the points of the last sweep from index `from` on (one page).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GetSweep {
    /// First point to return.
    pub from: u16,
}

/// One measured sweep point.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SweepPoint {
    /// Drive frequency, mHz.
    pub freq_mhz: u32,
    /// The response; `None` if the sensor gave none at this point.
    pub measured: Option<Measurement>,
}

/// A page of sweep points.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SweepPage {
    /// The sweep's run number (0: no sweep since reset).
    pub run: RunNumber,
    /// Points the sweep has.
    pub total: u16,
    /// Points measured so far (the sweep is complete when `done == total`).
    pub done: u16,
    /// Points from the requested index on.
    pub points: heapless::Vec<SweepPoint, SWEEP_PAGE>,
}

/// A fault to simulate, for tests of the fault monitors (the QEMU board only; a real board
/// refuses it with [`Refusal::Unsupported`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TestFault {
    /// The shaker's wires are cut: the plate gets no force.
    ShakerDisconnected,
    /// The amplifier clips at a fiftieth of full scale.
    AmplifierSaturated,
    /// The accelerometer stops producing samples.
    SensorSilent,
    /// The accelerometer answers with another device's id (seen at its next initialisation).
    SensorWrongId,
    /// A task stops checking in with the watchdog.
    StallTask,
    /// Undo every simulated fault.
    Heal,
}

/// Injects a simulated fault (QEMU only).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct InjectFault(pub TestFault);

/// Runs a stored plan.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RunPlan {
    /// Which plan.
    pub plan: PlanRef,
    /// Repeat count instead of the stored one.
    pub repeat: Option<u16>,
}

/// Ramps the drive to zero and idles (clears a fault). Taken from any session.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Stop;

/// Asks for the drive's [`StatusReport`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GetStatus;

/// Ends an upload: checks it whole and stores it (old plan or new, never a mix).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct UploadCommit;

/// Lists stored plans from slot `from_slot` on (one page; follow [`PlanPage::next`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ListPlans {
    /// First slot to list.
    pub from_slot: u8,
}

/// Deletes a stored plan (answered with what was deleted).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DeletePlan {
    /// Which plan.
    pub plan: PlanRef,
}

/// Asks for `count` telemetry samples at `rate_hz` (replacing any stream; `count` 0 stops it).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Subscribe {
    /// Samples per second, 1..=[`MAX_TELEMETRY_HZ`].
    pub rate_hz: u16,
    /// Samples to send, then the stream ends.
    pub count: u32,
}

/// Asks for the stored configuration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GetConfig;

/// Replaces the configuration (checked, stored, then applied); answered with it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SetConfig(pub DeviceConfig);

/// Asks what the plan store's flash area holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GetStore;

/// Erases the whole plan store (every plan and the configuration, or whatever else the area
/// held) and formats it for this firmware's store.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FormatStore;

/// The number the controller gives a drive command (`Drive`, `RunPlan`, `Stop`) when it
/// accepts it; [`StatusReport::run`] says which one is in effect.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RunNumber(pub u32);

endpoints! {
    /// Opens a session → the device's identity.
    Hello(Hello) => DeviceInfo, Anyone, fn hello;
    /// Liveness → the nonce.
    Ping(Ping) => u32, Anyone, fn ping;
    /// Identity.
    GetInfo(GetInfo) => DeviceInfo, Anyone, fn get_info;
    /// Ends ownership.
    Release(Release) => (), Anyone, fn release;
    /// Manual drive → its run number.
    Drive(Drive) => RunNumber, Owner, fn drive;
    /// Runs a stored plan → its run number.
    RunPlan(RunPlan) => RunNumber, Owner, fn run_plan;
    /// Stop → its run number (from any session: the shaker can always be stopped).
    Stop(Stop) => RunNumber, Anyone, fn stop;
    /// The drive's status.
    Status(GetStatus) => StatusReport, Anyone, fn status;
    /// Begins an upload → the slot it will go to.
    UploadBegin(UploadBegin) => u8, Owner, fn upload_begin;
    /// One chunk of steps → how many steps are in so far.
    UploadChunk(UploadChunk) => u16, Owner, fn upload_chunk;
    /// Commits the upload → the stored plan.
    UploadCommit(UploadCommit) => PlanSummary, Owner, fn upload_commit;
    /// One page of the plan list.
    ListPlans(ListPlans) => PlanPage, Anyone, fn list_plans;
    /// Deletes a plan → what was deleted.
    DeletePlan(DeletePlan) => PlanSummary, Owner, fn delete_plan;
    /// Starts (or ends) the telemetry stream.
    Subscribe(Subscribe) => (), Anyone, fn subscribe;
    /// The configuration.
    GetConfig(GetConfig) => DeviceConfig, Anyone, fn get_config;
    /// Sets the configuration → the configuration now in effect.
    SetConfig(SetConfig) => DeviceConfig, Owner, fn set_config;
    /// Clears a latched fault → its run number.
    ClearFault(ClearFault) => RunNumber, Owner, fn clear_fault;
    /// Starts a frequency sweep → its run number.
    Sweep(Sweep) => RunNumber, Owner, fn sweep;
    /// A page of the last sweep's points.
    GetSweep(GetSweep) => SweepPage, Anyone, fn get_sweep;
    /// Simulates a fault (QEMU only).
    InjectFault(InjectFault) => (), Owner, fn inject_fault;
    /// What the plan store's flash area holds.
    GetStore(GetStore) => StoreInfo, Anyone, fn get_store;
    /// Erases the plan store's area and writes its format marker → the store as it now is.
    FormatStore(FormatStore) => StoreInfo, Owner, fn format_store;
}

/// Why a request that was read was not carried out.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Refusal {
    /// Another session owns the controller.
    Busy {
        /// The owner's name from its `Hello` (empty if it sent none).
        owner: heapless::String<MAX_CLIENT_NAME>,
        /// How long ago the owner's last request arrived, ms; ownership lapses at
        /// [`OWNER_LEASE_MS`].
        idle_ms: u32,
    },
    /// The drive refused the command.
    Drive(DriveError),
    /// An upload request was refused.
    Upload(UploadError),
    /// The store could not do it.
    Store(StoreError),
    /// The configuration was refused.
    Config(ConfigError),
    /// The telemetry rate is outside 1..=[`MAX_TELEMETRY_HZ`].
    TelemetryRate {
        /// The rate asked for.
        rate_hz: u16,
    },
    /// The sweep was refused.
    Sweep(SweepError),
    /// This controller cannot do that (e.g. simulated faults on a real board).
    Unsupported,
}

/// Why a sweep was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SweepError {
    /// Fewer than 2 or more than [`MAX_SWEEP_POINTS`] points.
    Points {
        /// Points asked for.
        points: u16,
    },
    /// The range is empty (`from` not below `to`).
    Range {
        /// From, mHz.
        from_mhz: u32,
        /// To, mHz.
        to_mhz: u32,
    },
    /// The dwell is outside 10..=10 000 ms.
    Dwell {
        /// Dwell asked for, ms.
        dwell_ms: u32,
    },
}

impl core::fmt::Display for SweepError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            SweepError::Points { points } => {
                write!(f, "{points} sweep points: give 2..={MAX_SWEEP_POINTS}")
            }
            SweepError::Range { from_mhz, to_mhz } => write!(
                f,
                "sweep from {}.{:03} Hz to {}.{:03} Hz: the start must be below the end",
                from_mhz / 1000,
                from_mhz % 1000,
                to_mhz / 1000,
                to_mhz % 1000
            ),
            SweepError::Dwell { dwell_ms } => {
                write!(f, "dwell {dwell_ms} ms per point: give 10..=10000 ms")
            }
        }
    }
}

impl Sweep {
    /// Checks the sweep's shape (the device limits are checked on each point's setpoint).
    pub fn check(&self) -> Result<(), SweepError> {
        if self.points < 2 || self.points > MAX_SWEEP_POINTS {
            return Err(SweepError::Points { points: self.points });
        }
        if self.from_mhz >= self.to_mhz {
            return Err(SweepError::Range { from_mhz: self.from_mhz, to_mhz: self.to_mhz });
        }
        if !(10..=10_000).contains(&self.dwell_ms) {
            return Err(SweepError::Dwell { dwell_ms: self.dwell_ms });
        }
        Ok(())
    }

    /// Frequency of point `i`, mHz: geometric spacing (equal steps on the Bode plot's log
    /// axis), computed in f32 with libm's `powf` (the same bits on the host and the controller)
    /// and rounded; the first and last are exact.
    pub fn freq_mhz(&self, i: u16) -> u32 {
        if i == 0 {
            return self.from_mhz;
        }
        if i + 1 >= self.points {
            return self.to_mhz;
        }
        let ratio = self.to_mhz as f32 / self.from_mhz as f32;
        let t = i as f32 / (self.points - 1) as f32;
        (self.from_mhz as f32 * libm::powf(ratio, t) + 0.5) as u32
    }
}

impl core::fmt::Display for Refusal {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Refusal::Busy { owner, idle_ms } => {
                let owner = if owner.is_empty() { "another client" } else { owner.as_str() };
                write!(
                    f,
                    "the controller is busy: {owner} holds it (last request {idle_ms} ms ago)"
                )
            }
            Refusal::Drive(e) => write!(f, "{e}"),
            Refusal::Upload(e) => write!(f, "upload refused: {e}"),
            Refusal::Store(e) => write!(f, "{e}"),
            Refusal::Config(e) => write!(f, "configuration refused: {e}"),
            Refusal::TelemetryRate { rate_hz } => {
                write!(f, "telemetry rate {rate_hz} Hz is outside 1..={MAX_TELEMETRY_HZ} Hz")
            }
            Refusal::Sweep(e) => write!(f, "sweep refused: {e}"),
            Refusal::Unsupported => write!(f, "this controller does not support that request"),
        }
    }
}

/// One telemetry sample.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Telemetry {
    /// Sample number in this stream, from 0 (a gap means samples were lost).
    pub seq: u32,
    /// Samples still to come after this one.
    pub left: u32,
    /// The drive's status at the sample.
    pub status: StatusReport,
}

// ---- The drive's status and refusals ----

/// What the drive is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DriveState {
    /// No output (mid-scale).
    Idle,
    /// Amplitude rising towards the step's (or setpoint's) target.
    RampUp,
    /// Steady amplitude.
    Running,
    /// Amplitude falling towards a lower target within a plan or setpoint.
    RampDown,
    /// Ramping to zero after a stop request or the end of a plan; then idle.
    Stopping,
    /// Ramped to zero after a fault; stays silent until `ClearFault` clears it (a stop does not).
    Faulted,
}

impl DriveState {
    /// Lowercase name as printed by the CLI (`stopping` is reported as `ramp_down`).
    pub const fn name(self) -> &'static str {
        match self {
            DriveState::Idle => "idle",
            DriveState::RampUp => "ramp_up",
            DriveState::Running => "running",
            DriveState::RampDown | DriveState::Stopping => "ramp_down",
            DriveState::Faulted => "faulted",
        }
    }
}

/// A snapshot of the drive, as answered to [`Request::Status`].
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StatusReport {
    /// What the drive is doing.
    pub state: DriveState,
    /// Index of the plan step being run; `None` outside a plan (idle, manual, final ramp).
    pub step: Option<u16>,
    /// Which repetition of the plan is running (0-based).
    pub repetition: u16,
    /// The run number of the drive command in effect (0: none since reset).
    pub run: RunNumber,
    /// Name of the plan being run; `None` outside a plan.
    pub plan: Option<PlanName>,
    /// Samples left until the plan's last step ends (0 outside a plan).
    pub remaining_samples: u64,
    /// The latched fault: set when the drive faulted, kept until a `ClearFault`.
    pub fault: Option<Fault>,
    /// The setpoint in effect now (an acceleration target as ramped so far); `None` when the
    /// drive is idle, stopping or faulted.
    pub level: Option<Level>,
    /// The plate's response at the drive frequency (lock-in), when the sensor has one.
    pub measured: Option<Measurement>,
    /// The closed-loop response is outside the warning band around its target.
    pub warning: bool,
    /// Why the controller last started.
    pub reset_cause: ResetCause,
    /// The drive's sample clock (samples since the controller started), the time base of
    /// [`Fault::at_sample`].
    pub clock: u64,
    /// Samples output since the current plan or manual drive started (kept when idle).
    pub elapsed_samples: u64,
    /// Samples per second, to turn `elapsed_samples` into time.
    pub sample_rate: u32,
    /// Frequency being output, millihertz.
    pub freq_mhz: u32,
    /// Amplitude being output right now (ramps included), Q15.
    pub amplitude_q15: u16,
    /// Sample blocks the output needed before they were ready (missed refills).
    pub underruns: u32,
    /// Commands applied so far (start, drive, stop, fault).
    pub commands: u32,
    /// The least refill slack since the controller started, µs: how long before the output
    /// would have run dry a block was handed over (`None` before the first block).
    pub least_slack_us: Option<u32>,
    /// The stack's high water since the controller started, bytes (0: not measured).
    pub stack_high_water: u32,
}

impl StatusReport {
    /// The status of a controller that has not driven since it started.
    pub const IDLE: StatusReport = StatusReport {
        state: DriveState::Idle,
        step: None,
        repetition: 0,
        run: RunNumber(0),
        plan: None,
        remaining_samples: 0,
        fault: None,
        level: None,
        measured: None,
        warning: false,
        reset_cause: ResetCause::PowerOn,
        clock: 0,
        elapsed_samples: 0,
        sample_rate: crate::icd::units::SAMPLE_RATE,
        freq_mhz: 0,
        amplitude_q15: 0,
        underruns: 0,
        commands: 0,
        least_slack_us: None,
        stack_high_water: 0,
    };

    /// `elapsed_samples` in milliseconds.
    pub fn elapsed_ms(&self) -> f64 {
        crate::icd::units::ms_from_samples(self.elapsed_samples, self.sample_rate)
    }

    /// `remaining_samples` in milliseconds.
    pub fn remaining_ms(&self) -> f64 {
        crate::icd::units::ms_from_samples(self.remaining_samples, self.sample_rate)
    }
}

/// Why a command was not applied.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DriveError {
    /// The plan does not fit the device's limits.
    Plan(PlanError),
    /// The manual setpoint does not fit the device's limits.
    Setpoint(SetpointError),
    /// A fault is latched; clear it (`ClearFault`) first.
    Faulted,
    /// The drive's command queue is full; try again.
    QueueFull,
}

impl core::fmt::Display for DriveError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            DriveError::Plan(e) => write!(f, "invalid plan: {e}"),
            DriveError::Setpoint(e) => write!(f, "invalid setpoint: {e}"),
            DriveError::Faulted => {
                write!(f, "a fault is latched (clear it first: chladni device clear-fault)")
            }
            DriveError::QueueFull => write!(f, "drive command queue full (try again)"),
        }
    }
}

// ---- Device identity ----

/// Which hardware the firmware was built for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Board {
    /// The B-L475E-IOT01A discovery kit (STM32L475VG).
    Stm32l475,
    /// The same application on `qemu-system-arm -M b-l475e-iot01a`, with a simulated shaker.
    Qemu,
}

impl Board {
    /// Short lowercase name, as used by the CLI and the firmware's cargo features.
    pub const fn name(self) -> &'static str {
        match self {
            Board::Stm32l475 => "stm32l475",
            Board::Qemu => "qemu",
        }
    }
}

/// Identity of the running firmware.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DeviceInfo {
    /// Firmware crate version (semver).
    pub firmware_version: heapless::String<24>,
    /// Board the firmware runs on.
    pub board: Board,
    /// [`PROTOCOL_VERSION`] of the firmware.
    pub protocol_version: u16,
    /// First 32 bits of the git commit the firmware was built from (0 if unknown).
    pub build_id: u32,
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    fn round_trip(body: Response) {
        let env = Envelope { version: PROTOCOL_VERSION, session: 5, id: 99, body };
        let mut buf = [0u8; ENCODE_BUF];
        let bytes = encode(&env, &mut buf).unwrap().to_vec();
        let mut frame = bytes[1..bytes.len() - 1].to_vec();
        assert_eq!(decode::<Response>(&mut frame), Ok(env));
    }

    #[test]
    fn responses_round_trip() {
        round_trip(Response::GetInfo(DeviceInfo {
            firmware_version: "0.1.0".try_into().unwrap(),
            board: Board::Qemu,
            protocol_version: PROTOCOL_VERSION,
            build_id: 0x1234_5678,
        }));
        round_trip(Response::Refused(Refusal::Busy { owner: "x".try_into().unwrap(), idle_ms: 7 }));
        round_trip(Response::Stop(RunNumber(3)));
    }

    /// The worked example of docs/protocol.md, byte for byte.
    #[test]
    fn documented_ping_frame() {
        let env = Envelope {
            version: PROTOCOL_VERSION,
            session: 0x1234_5678,
            id: 1,
            body: Request::Ping(Ping { nonce: 0x0102_0304 }),
        };
        let mut buf = [0u8; ENCODE_BUF];
        let wire = encode(&env, &mut buf).unwrap();
        assert_eq!(
            wire,
            [
                0x00, 0x11, 0x06, 0xf8, 0xac, 0xd1, 0x91, 0x01, 0x01, 0x01, 0x84, 0x86, 0x88, 0x08,
                0x62, 0xc3, 0x93, 0xde, 0x00
            ]
        );
        // Variant numbers are the table's order: a client in another language relies on them.
        let requests = [
            Request::Hello(Hello { client: heapless::String::new() }),
            Request::Ping(Ping { nonce: 0 }),
            Request::GetInfo(GetInfo),
            Request::Release(Release),
            Request::Drive(Drive { freq_mhz: 0, level: Level::Drive(0) }),
            Request::RunPlan(RunPlan { plan: crate::icd::store::PlanRef::Slot(0), repeat: None }),
            Request::Stop(Stop),
            Request::Status(GetStatus),
            Request::UploadCommit(UploadCommit),
            Request::ListPlans(ListPlans { from_slot: 0 }),
            Request::Subscribe(Subscribe { rate_hz: 1, count: 1 }),
            Request::GetConfig(GetConfig),
            Request::ClearFault(ClearFault),
            Request::GetSweep(GetSweep { from: 0 }),
            Request::InjectFault(InjectFault(TestFault::Heal)),
            Request::GetStore(GetStore),
            Request::FormatStore(FormatStore),
        ];
        let numbers: std::vec::Vec<u8> =
            requests.iter().map(|r| postcard::to_stdvec(r).unwrap()[0]).collect();
        assert_eq!(numbers, [0, 1, 2, 3, 4, 5, 6, 7, 10, 11, 13, 14, 16, 18, 19, 20, 21]);
        let error = postcard::to_stdvec(&Response::Error(LinkError::BadCrc)).unwrap();
        let refused =
            postcard::to_stdvec(&Response::Refused(Refusal::TelemetryRate { rate_hz: 0 }));
        assert_eq!((error[0], refused.unwrap()[0]), (22, 23));
        let level = postcard::to_stdvec(&Level::Accel(1)).unwrap();
        assert_eq!(level, [1, 1]);
    }

    #[test]
    fn each_request_names_its_response() {
        let pong = <Ping as Endpoint>::respond(0xfeed);
        assert_eq!(pong, Response::Ping(0xfeed));
        assert_eq!(Ping::reply(pong), Ok(0xfeed));
        // Another request's answer is handed back, not misread.
        assert_eq!(GetStatus::reply(Response::Ping(1)), Err(Response::Ping(1)));
        assert_eq!(Ping { nonce: 1 }.into_request().name(), "Ping");
        assert!(Drive { freq_mhz: 1, level: Level::Drive(1) }.into_request().needs_owner());
        assert!(!Stop.into_request().needs_owner());
        assert!(!GetStatus.into_request().needs_owner());
        assert!(ClearFault.into_request().needs_owner());
        let sweep = GetSweep { from: 0 }.into_request();
        assert!(sweep.is_answered_by(&GetSweep::respond(SweepPage {
            run: RunNumber(1),
            total: 0,
            done: 0,
            points: heapless::Vec::new(),
        })));
        assert!(!sweep.is_answered_by(&Response::Ping(1)));
        assert!(!sweep.is_answered_by(&Response::Refused(Refusal::Unsupported)));
    }

    #[test]
    fn sweep_points_are_geometric_and_end_exactly() {
        let s = Sweep {
            from_mhz: 50_000,
            to_mhz: 500_000,
            points: 101,
            amplitude_q15: 1,
            dwell_ms: 50,
        };
        assert_eq!(s.check(), Ok(()));
        assert_eq!((s.freq_mhz(0), s.freq_mhz(100)), (50_000, 500_000));
        for i in 1..100 {
            let want = 50_000.0 * 10f64.powf(i as f64 / 100.0);
            let got = s.freq_mhz(i) as f64;
            assert!((got - want).abs() / want < 1e-5, "point {i}: {got} vs {want}");
        }
        let bad = Sweep { points: 1, ..s };
        assert_eq!(bad.check(), Err(SweepError::Points { points: 1 }));
        let bad = Sweep { from_mhz: 500_000, ..s };
        assert!(matches!(bad.check(), Err(SweepError::Range { .. })));
        let bad = Sweep { dwell_ms: 5, ..s };
        assert_eq!(bad.check(), Err(SweepError::Dwell { dwell_ms: 5 }));
    }
}
