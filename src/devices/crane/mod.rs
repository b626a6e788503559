//! The stacker crane adapter (spec: crane-mc3e.md): one task at a time, handed over with
//! the STB/ACK handshake and followed by polling D200..D239, over any [`PlcMemory`] (MC 3E
//! over TCP or UDP in practice).
//!
//! Answers to the questions the spec leaves open:
//! - **Task number**: derived from the job id like the shelf's task id
//!   ([`crate::wire::task_id_for`]), so the crane's echo (D208) leads back
//!   to the job after a restart with no extra record.
//! - **Modes**: store = transfer from the inbound station into the rack, retrieve = transfer
//!   from the rack to the outbound station, move = transfer rack to rack, travel = mode 1
//!   with "from" zero. The location's position is the crane's side (1 near, 2 far).
//! - **Hand-over**: only to a strictly idle, clean crane (ACK D225 = 0, D203 = 0, D208 =
//!   0, D223 = 0, no alarm; rackd's strobe down, no earlier hand-over pending), heartbeat
//!   alive, link up, not paused. Words D8..D17 in one write, then STB := 1, wait ACK = 1,
//!   STB := 0, wait ACK = 0, each wait bounded by `handshake_timeout_ms`. A step that fails
//!   (timeout, link loss) does NOT lower the strobe at once (that would start a task a
//!   crane latched): the hand-over stays pending and each poll carries it on by the table
//!   in [`interrupted`]; without ACK the strobe is withdrawn after the timeout and the job
//!   stays *possibly latched* (followed, not handed over again, no other task) until the
//!   crane shows strictly idle a handshake timeout later; a task the crane latched is
//!   followed and never sent twice.
//! - **Acknowledgement**: see [`ack`]; the outcome is stored before D22 is written.
//! - **Alarms**: see [`alarms`]. A business alarm with `auto_cancel` sends mode 3 through
//!   the same handshake and moves the job to `cancelling`; when the crane reports 40 the job
//!   fails with kind `alarm`, the code and the catalogue text. A hardware alarm (or an
//!   unknown code) only stops new work until D205 is 0 again. Any alarm is shown in the
//!   device status; a crane with an alarm gets no new work.
//! - **Cancel through the API**: a queued job is cancelled at once; the job the crane holds
//!   gets mode 3 (job `cancelling`), and `cancelled` once 40 is acknowledged. A crane that
//!   completes before it sees the cancel completes the job (cancelling → completed). A job
//!   whose hand-over is pending (possibly latched) is refused as not taken until the
//!   hand-over is over: only then is it known whether the crane holds it.
//! - **When the crane shows its task**: the spec does not say whether D208 echoes the task
//!   at step 2 or only when it starts. rackd takes either: a task the crane latched (it
//!   answered ACK = 1) is held without D208 for up to a handshake timeout after the
//!   hand-over before it counts as lost, and no other task is handed over meanwhile.
//! - **Heartbeat**: see [`heartbeat`]. While lost the device is offline (no new work) and
//!   the status says so; a task under way is not failed, since the crane may still be
//!   running it; rackd follows it again once the heartbeat moves.
//! - **Words left alone**: D20 (execute action) stays 0, since the spec gives it no role in
//!   the hand-over; D201, D202 and D224 are read but not interpreted.
//! - **Status**: the device status carries a `crane` object (heartbeat, and while it is
//!   lost `heartbeat_stalled_since`, the wall-clock time D200 last changed; action state and
//!   its text, positions D220/D221, load D206, task D208, alarm code/text/class). The
//!   crane's block is read and shown at every poll that the link answers, heartbeat or
//!   not, so an alarm such as 7020 reaches the status while the device is offline. Each new
//!   action state of the held task is logged, and the first one is the `running` cause in
//!   the job's history.
//! - **Recovery**: on start, before anything may be dispatched, rackd reads both blocks;
//!   its own D0 and D22 are taken as written, a task the crane holds (D208) whose number
//!   belongs to an unfinished job is followed (its pending completion is recorded and
//!   acknowledged), and an interrupted hand-over is rebuilt from D8..D17, D21, D225 and
//!   D208 and finished by the same table ([`interrupted`]): STB=1 ACK=0 waits for the
//!   crane's ACK as that job (then withdraws, possibly latched); STB=1 ACK=1 lowers the
//!   strobe (the crane latched D8's task) and follows the job; STB=0 ACK=1 follows the
//!   job while the crane starts it; mode 3 ends with the job `cancelling`. A strobe found
//!   up for words that are no unfinished job of rackd's is left alone: nothing is
//!   dispatched and `last_error` says so until a person clears D21. Unfinished jobs past
//!   `queued` that the crane does not hold fail as `lost`. A cancel under way for a
//!   business alarm is not remembered across a restart: such a job ends `cancelled`
//!   rather than `failed`.

pub mod ack;
mod follow;
mod handshake;
pub mod heartbeat;
mod interrupted;
mod work;

use std::sync::Arc;

use tokio::sync::mpsc;
use tokio::time::{Instant, sleep_until};
use tracing::Instrument;

use super::DeviceRequest;
use super::port::{Port, ReportError};
use super::repeats::Repeats;
use super::status::{CraneStatus, StatusCell};
use crate::config::devices::{Ack, CraneConfig};
use crate::domain::{Failure, Report, Reported};
use crate::protocols::{Address, PlcError, PlcMemory};
use crate::wire::alarms;
use crate::wire::registers::{self, CraneView, Stations};
use heartbeat::Heartbeat;

pub use handshake::HandshakeError;

/// The device's error while the crane's heartbeat stands still.
const HEARTBEAT_LOST: &str = "the crane's heartbeat (D200) stopped moving: crane lost";

/// Why a step of the crane adapter stopped.
#[derive(Debug, thiserror::Error)]
pub enum CraneError {
    /// The PLC did not answer or refused.
    #[error(transparent)]
    Plc(#[from] PlcError),
    /// The hand-over handshake did not complete.
    #[error(transparent)]
    Handshake(#[from] HandshakeError),
    /// The dispatcher could not record a report.
    #[error(transparent)]
    Report(#[from] ReportError),
}

/// The job the crane holds (or was just handed).
#[derive(Clone, Debug, PartialEq)]
struct Current {
    job: i64,
    task: registers::Task,
    /// The crane was seen holding it (its D208 showed the number).
    seen: bool,
    /// When the crane was known to have latched it (ACK = 1 for its words): a crane may
    /// show the task in D208 only as it starts it, so until a handshake timeout later an
    /// empty D208 is not taken for a lost task.
    latched_at: Option<Instant>,
    /// A cancel (mode 3) was handed over.
    cancel_sent: bool,
    /// The business alarm that cancelled it: the job fails with this at 40.
    alarm: Option<Failure>,
    /// The last action state recorded, so each change is logged once.
    action: u16,
}

/// One stacker crane: its link, what it holds and its port to the dispatcher.
pub struct Crane {
    config: CraneConfig,
    plc: Arc<dyn PlcMemory>,
    wcs: Address,
    crane: Address,
    port: Arc<dyn Port>,
    status: StatusCell,
    stations: Stations,
    ack: Ack,
    heartbeat: Heartbeat,
    current: Option<Current>,
    /// What D22 holds as rackd last wrote it; `None` while a write of it is unanswered
    /// (it may have landed or not: the next poll writes the word wanted again, and no task
    /// is handed over meanwhile, since a 1 left standing would acknowledge the next task's
    /// completion for rackd).
    ack_written: Option<u16>,
    link_ok: bool,
    view: Option<CraneView>,
    /// A hand-over not known to be over (see [`interrupted`]): no other until it is.
    handing: Option<interrupted::Handing>,
    /// Why no work may be handed over until a person clears rackd's strobe at the crane.
    blocked: Option<String>,
    /// Wall-clock time the crane's heartbeat (D200) last changed (or rackd began to watch).
    heartbeat_moved: time::OffsetDateTime,
    /// Failures of recovery, polls and hand-overs, logged without flooding.
    repeats: Repeats,
}

impl Crane {
    /// A crane adapter; nothing is sent until [`Crane::run`].
    pub fn new(
        config: CraneConfig,
        plc: Arc<dyn PlcMemory>,
        port: Arc<dyn Port>,
        status: StatusCell,
    ) -> Result<Crane, CraneError> {
        let wcs = plc.parse_address(&config.wcs_base)?;
        let crane = plc.parse_address(&config.crane_base)?;
        let ack = config.ack;
        let stations =
            Stations { inbound: config.inbound_station.words(), outbound: config.outbound_station.words() };
        let heartbeat = Heartbeat::new(
            std::time::Duration::from_millis(config.heartbeat_ms),
            std::time::Duration::from_millis(config.heartbeat_timeout_ms),
            Instant::now(),
        );
        Ok(Crane {
            config,
            plc,
            wcs,
            crane,
            port,
            status,
            stations,
            ack,
            heartbeat,
            current: None,
            ack_written: None,
            link_ok: false,
            view: None,
            handing: None,
            blocked: None,
            heartbeat_moved: crate::domain::time::from_ms(crate::domain::time::now_ms()),
            repeats: Repeats::default(),
        })
    }

    /// Runs the device until the task is aborted or asked to stop: recover, then poll at
    /// the configured period, hand over work when the crane is free, and answer requests.
    ///
    /// A stop ([`DeviceRequest::Stop`]) ends it between two rounds, never inside a
    /// hand-over's handshake: while a hand-over is not known to be over ([`interrupted`]),
    /// the task hands over nothing new and keeps polling, which carries the hand-over to
    /// its end, and stops then. Should the crane not answer for [`Crane::stop_grace`], it
    /// stops anyway: the registers hold the hand-over, and the next start rebuilds and
    /// finishes it from them, as after a restart.
    pub async fn run(mut self, mut requests: mpsc::Receiver<DeviceRequest>) {
        let period = self.config.poll();
        let mut later = Vec::new();
        while let Err(e) = self.recover().await {
            self.repeats.failed("crane recovery failed; retrying", &e);
            self.status.update(|s| s.last_error = Some(e.to_string()));
            if super::wait_recovering(period, &mut requests, &mut later).await {
                return;
            }
        }
        self.repeats.recovered();
        let mut stopping = None;
        for request in later {
            self.handle(request, &mut stopping).await;
        }
        let mut next_poll = Instant::now() + period;
        loop {
            if let Some(deadline) = stopping {
                if self.handing.is_none() {
                    tracing::info!("stopped (reload)");
                    return;
                }
                if Instant::now() >= deadline {
                    tracing::warn!("stopped (reload) with a hand-over not over: the next start finishes it");
                    return;
                }
            }
            let port = self.port.clone();
            let span = self.job_span();
            tokio::select! {
                Some(request) = requests.recv() => self.handle(request, &mut stopping).instrument(span).await,
                _ = port.work_waiting() => {}
                _ = sleep_until(next_poll) => {
                    match self.poll().instrument(span).await {
                        Ok(()) => self.repeats.recovered(),
                        Err(e) => {
                            self.repeats.failed("crane poll failed", &e);
                            self.status.update(|s| s.last_error = Some(e.to_string()));
                        }
                    }
                    next_poll = Instant::now() + period;
                }
            }
            if stopping.is_none()
                && self.may_dispatch()
                && let Err(e) = self.dispatch().await
            {
                self.repeats.failed("crane hand-over stopped", &e);
                self.status.update(|s| s.last_error = Some(e.to_string()));
            }
        }
    }

    /// How long a stop waits for a hand-over under way to end: three handshake timeouts
    /// (the wait for ACK = 1, the wait for ACK = 0 or the withdrawn strobe's hold) and two
    /// polls; a crane that answers ends any hand-over within it.
    pub fn stop_grace(&self) -> std::time::Duration {
        3 * std::time::Duration::from_millis(self.config.handshake_timeout_ms) + 2 * self.config.poll()
    }

    /// The span of the job the crane holds, so that what is logged about it carries its
    /// id; none while it holds nothing of rackd's.
    fn job_span(&self) -> tracing::Span {
        match &self.current {
            Some(c) => tracing::info_span!("job", job = c.job),
            None => tracing::Span::none(),
        }
    }

    /// Answers a request; a stop sets when the task must stop at the latest.
    async fn handle(&mut self, request: DeviceRequest, stopping: &mut Option<Instant>) {
        match request {
            DeviceRequest::Cancel { job, reply } => {
                let _ = reply.send(self.cancel(job).await);
            }
            DeviceRequest::Holding { mut jobs, reply } => {
                let current = self.current.as_ref().map(|c| c.job);
                let handing = self.handing.as_ref().map(|h| h.job);
                jobs.retain(|id| current == Some(*id) || handing == Some(*id));
                let _ = reply.send(jobs);
            }
            DeviceRequest::Stop => {
                if stopping.is_none() {
                    *stopping = Some(Instant::now() + self.stop_grace());
                }
            }
        }
    }

    /// New work only to a reachable, live, strictly idle crane without alarm: rackd's
    /// strobe down with no hand-over under way or unaccounted for, no completion being
    /// acknowledged, and the crane's ACK, task echo, action state and D223 at 0 (the
    /// dispatcher offers none while the crane is paused).
    fn may_dispatch(&self) -> bool {
        let idle = self.view.is_some_and(|v| v.is_idle());
        let clear = self.handing.is_none() && self.blocked.is_none() && self.ack_written == Some(0);
        self.status.get().online && self.current.is_none() && idle && clear
    }

    /// Word `n` of the block the WCS writes (D0..), in the protocol's addressing.
    fn wcs_word(&self, n: u32) -> Address {
        self.plc.word_address(&self.wcs, n)
    }

    /// Word `n` of the block the crane writes (D200..), in the protocol's addressing.
    fn crane_word(&self, n: u32) -> Address {
        self.plc.word_address(&self.crane, n)
    }

    /// Reads words, keeping the device's contact status.
    async fn read(&mut self, at: &Address, count: u16) -> Result<Vec<u16>, PlcError> {
        let result = self.plc.read_words(at, count).await;
        self.contact(result.as_ref().map(|_| ()));
        result
    }

    /// Writes words, keeping the device's contact status.
    async fn write(&mut self, at: &Address, values: &[u16]) -> Result<(), PlcError> {
        let result = self.plc.write_words(at, values).await;
        self.contact(result.as_ref().map(|_| ()));
        result
    }

    fn contact(&mut self, result: Result<(), &PlcError>) {
        let offline_after = self.config.offline_after;
        let mut link_ok = self.link_ok;
        let link = self.plc.link_stats();
        self.status.update(|s| {
            link_ok = s.record_contact(result, offline_after, link_ok, link);
        });
        if link_ok && !self.link_ok {
            // Unseen while the link was down is not stalled: no heartbeat alarm after every
            // outage.
            self.heartbeat.restart(Instant::now());
        }
        self.link_ok = link_ok;
        self.show_online();
    }

    /// Online = the link answers and the crane's heartbeat moves.
    fn show_online(&mut self) {
        let lost = self.heartbeat.is_lost(Instant::now());
        let link_ok = self.link_ok;
        let stalled_since = lost.then_some(self.heartbeat_moved);
        self.status.update(|s| {
            let online = link_ok && !lost;
            if lost {
                s.last_error = Some(HEARTBEAT_LOST.into());
            } else if s.last_error.as_deref() == Some(HEARTBEAT_LOST) {
                // The heartbeat moves again: its error is over (`last_error_at` keeps when).
                s.last_error = None;
            }
            if online != s.online {
                if online {
                    tracing::info!("crane online");
                } else {
                    tracing::warn!(link_ok, heartbeat_lost = lost, "crane offline");
                }
            }
            s.online = online;
            if let Some(c) = s.crane.as_mut() {
                c.heartbeat_ok = !lost;
                c.heartbeat_stalled_since = stalled_since;
            }
        });
    }

    /// Shows what the crane reports in the device status.
    fn show(&mut self, v: &CraneView) {
        let alarm = (v.alarm != 0).then(|| alarms::lookup(v.alarm));
        self.status.update(|s| {
            let heartbeat_ok = s.crane.as_ref().is_some_and(|c| c.heartbeat_ok);
            let heartbeat_stalled_since = s.crane.as_ref().and_then(|c| c.heartbeat_stalled_since);
            s.crane = Some(CraneStatus {
                known: true,
                heartbeat_ok,
                heartbeat_stalled_since,
                action_state: v.action,
                action: registers::action_text(v.action).to_owned(),
                travel_position: v.travel,
                lift_position: v.lift,
                load: v.load,
                task: v.task,
                alarm_code: alarm.as_ref().map(|a| a.code),
                alarm_text: alarm.as_ref().map(|a| a.text.clone()),
                alarm_class: alarm.as_ref().map(|a| a.class),
            });
            s.slots_in_use = u16::from(v.task != 0);
        });
        self.show_online();
    }

    /// Records what the crane shows of one job.
    async fn record(&self, job: i64, to: Reported, cause: impl Into<String>) -> Result<(), CraneError> {
        self.port.report(vec![Report::new(job, to, cause)]).await?;
        Ok(())
    }
}
