//! The ring of one control step, physics -> estimator -> planner -> physics, as the planner
//! drives it in lockstep: every mode that acts on frames waits, before it acts on a frame,
//! for the estimator's [`ObjectEstimate`] of that frame (matched by the frame's publish
//! stamp, unique per published frame even across resets). So the estimator has seen every
//! frame before the planner sends an event about it or the command that makes the next
//! frame, and draining events before each frame gives it the planner's events in order.
//!
//! On the realtime clock physics publishes frames whether commanded or not, so the frame
//! the driver takes and the estimates that come in may part: the ring then takes a later
//! frame until it holds one whose estimate is in and was made after the estimator read the
//! planner's last event ([`Ring`]'s `catch_up`). In lockstep that is always the frame the
//! last command made.
//!
//! Waiting: after a command or a reset the planner waits on the estimates' event service
//! only, never on the frames': the estimator acknowledges a frame only after physics
//! published it, so once the estimate of a frame newer than the latest is in, the new
//! frame is in the planner's subscriber too and is taken without waiting. Each physics
//! step thus wakes (or keeps spinning) one process, the estimator, not two competing for
//! the cores physics needs.

use std::time::Duration;

use agp_runtime::{
    AgpIpc, DriveError, Instance, LockstepDriver, WaitOutcome, WaitStrategy, Waiter, alloc_count,
};
use agp_shared_types::{
    IrFrame, LearnEvent, LearnReport, LearnReportKind, ObjectEstimate, Pose2, monotonic_ns, stage,
};
use anyhow::{Result, anyhow, bail};
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::Node;

/// The planner's ports to the estimator: events out, acknowledgements and reports in.
pub struct EstimatorLink {
    _node: Node<AgpIpc>,
    events: Publisher<AgpIpc, LearnEvent, ()>,
    wake: Notifier<AgpIpc>,
    estimates: Subscriber<AgpIpc, ObjectEstimate, ()>,
    estimates_waiter: Waiter,
    reports: Subscriber<AgpIpc, LearnReport, ()>,
    reports_waiter: Waiter,
    seq: u64,
    /// When the last event went out (CLOCK_MONOTONIC, taken once it was published; 0: none
    /// yet). The estimator drains events after it stamps a frame's receipt, so on one machine
    /// an estimate whose frame it received at or after this took the event in.
    sent_ns: u64,
    /// The session of the last event sent (its seq is `seq`).
    sent_session: u64,
    /// Publish stamp of the newest frame the estimator acknowledged.
    acked_stamp: u64,
    /// The estimate of that frame and when it was received (CLOCK_MONOTONIC), until the
    /// command answering the frame took its stamps.
    latest: Option<(ObjectEstimate, u64)>,
    /// The estimate of the newest frame acknowledged, kept.
    newest: Option<ObjectEstimate>,
    /// The latest trial counts the estimator reported.
    learned: u32,
    rejected: u32,
    timeout: Duration,
    /// Start time of the estimator that acknowledges (from its estimates; 0: none seen).
    estimator_start_ns: u64,
    /// Set when an estimate came from an estimator started after that one.
    estimator_restarted: bool,
}

/// The estimator restarted: it lost what it learned, so the protocol starts over (a new
/// session) rather than waiting for acknowledgements or reports it will never send.
#[derive(Debug)]
pub struct EstimatorRestarted;

impl std::fmt::Display for EstimatorRestarted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("the estimator restarted")
    }
}

impl std::error::Error for EstimatorRestarted {}

/// How long a wait for a report lasts before it looks again for a restarted estimator.
const REPORT_WAIT_SLICE: Duration = Duration::from_millis(20);

/// What [`take_estimates`] keeps track of.
#[derive(Debug, Clone, Copy)]
struct Acks {
    /// Publish stamp of the newest frame acknowledged.
    stamp: u64,
    /// That frame's estimate and its receipt, until taken.
    latest: Option<(ObjectEstimate, u64)>,
    /// That frame's estimate, kept.
    newest: Option<ObjectEstimate>,
    /// The acknowledging estimator's start time, and whether a later one appeared.
    estimator_start_ns: u64,
    restarted: bool,
}

fn open_err<E: std::fmt::Debug>(what: &'static str) -> impl FnOnce(E) -> anyhow::Error {
    move |e| anyhow!("cannot open {what}: {e:?}")
}

impl EstimatorLink {
    pub fn open(instance: &Instance, timeout: Duration) -> Result<Self> {
        let node = instance
            .node("planner-learn", false)
            .map_err(open_err("the learn node"))?;
        let events = instance
            .learn_events(&node)
            .map_err(open_err("the learn events"))?;
        let estimates = instance
            .estimates(&node)
            .map_err(open_err("the estimates"))?;
        let reports = instance
            .learn_reports(&node)
            .map_err(open_err("the learn reports"))?;
        let strategy = WaitStrategy::from_env();
        Ok(Self {
            events: events
                .data
                .publisher_builder()
                .create()
                .map_err(open_err("the learn event publisher"))?,
            wake: events
                .event
                .notifier_builder()
                .create()
                .map_err(open_err("the learn event notifier"))?,
            estimates: estimates
                .subscriber()
                .create()
                .map_err(open_err("the estimate subscriber"))?,
            estimates_waiter: Waiter::new(
                estimates
                    .event
                    .listener_builder()
                    .create()
                    .map_err(open_err("the estimate listener"))?,
                strategy,
            ),
            reports: reports
                .subscriber()
                .create()
                .map_err(open_err("the report subscriber"))?,
            reports_waiter: Waiter::new(
                reports
                    .event
                    .listener_builder()
                    .create()
                    .map_err(open_err("the report listener"))?,
                WaitStrategy::Block,
            ),
            seq: 0,
            sent_ns: 0,
            sent_session: 0,
            acked_stamp: 0,
            latest: None,
            newest: None,
            learned: 0,
            rejected: 0,
            timeout,
            estimator_start_ns: 0,
            estimator_restarted: false,
            _node: node,
        })
    }

    /// Waits until the estimator has seen `frame` (or a later one). Returns the estimator's
    /// estimate of `frame` itself and when it was received (CLOCK_MONOTONIC), once: the
    /// command answering `frame` carries its stamps.
    fn ack(&mut self, frame: &IrFrame) -> Result<Option<(ObjectEstimate, u64)>> {
        let _in_iceoryx2 = alloc_count::enter(alloc_count::Region::Iceoryx2);
        let stamp = frame.timing.stamps_ns[stage::FRAME_PUBLISHED];
        if self.acked_stamp < stamp {
            let estimates = &self.estimates;
            let mut acks = self.acks();
            let outcome = self.estimates_waiter.wait_for(self.timeout, || {
                take_estimates(estimates, &mut acks);
                (acks.stamp >= stamp || acks.restarted).then_some(())
            });
            self.set_acks(acks);
            self.check_estimator()?;
            match outcome {
                WaitOutcome::Ready(()) => {}
                WaitOutcome::Shutdown => return Err(DriveError::Shutdown.into()),
                WaitOutcome::TimedOut => return Err(self.no_ack(frame.step)),
            }
        }
        Ok(self
            .latest
            .take_if(|(e, _)| e.timing.stamps_ns[stage::FRAME_PUBLISHED] == stamp))
    }

    fn acks(&self) -> Acks {
        Acks {
            stamp: self.acked_stamp,
            latest: self.latest,
            newest: self.newest,
            estimator_start_ns: self.estimator_start_ns,
            restarted: self.estimator_restarted,
        }
    }

    fn set_acks(&mut self, a: Acks) {
        self.acked_stamp = a.stamp;
        self.latest = a.latest;
        self.newest = a.newest;
        self.estimator_start_ns = a.estimator_start_ns;
        self.estimator_restarted = a.restarted;
    }

    /// [`EstimatorRestarted`] once when an estimate showed a restarted estimator.
    fn check_estimator(&mut self) -> Result<()> {
        if std::mem::take(&mut self.estimator_restarted) {
            return Err(EstimatorRestarted.into());
        }
        Ok(())
    }

    fn no_ack(&self, step: u64) -> anyhow::Error {
        anyhow!(
            "the estimator did not acknowledge the frame of step {step} within {:?}: is `agp-estimator` running on this instance?",
            self.timeout
        )
    }

    /// Sends one event about `frame`.
    pub fn send(&mut self, mut event: LearnEvent, frame: &IrFrame) -> Result<()> {
        let _in_iceoryx2 = alloc_count::enter(alloc_count::Region::Iceoryx2);
        self.seq += 1;
        event.seq = self.seq;
        event.step = frame.step;
        event.ir_sample = frame.ir_sample;
        event.ir_raw = frame.ir_raw;
        event.odometry = frame.odometry;
        let sample = self
            .events
            .loan_uninit()
            .map_err(|e| anyhow!("cannot loan a learn event: {e:?}"))?;
        sample
            .write_payload(event)
            .send()
            .map_err(|e| anyhow!("cannot send a learn event: {e:?}"))?;
        let _ = self.wake.notify();
        self.sent_ns = monotonic_ns();
        self.sent_session = event.session;
        Ok(())
    }

    /// Whether the estimator made `e` after it took in the last event this link sent.
    /// - The estimator's newest event is of this link's session: exactly, by its seq.
    /// - Another planner's event came in after it (a swap under way), or none of this
    ///   session yet: by the clock, an estimate of a frame the estimator received after the
    ///   event was sent. That is exact on one machine, where a sent event is in the
    ///   estimator's queue, but not across a bridge: the event arrives a link's latency
    ///   later, and on the realtime clock physics publishes frames meanwhile (what the seq
    ///   is for).
    fn took_in_last_event(&self, e: &ObjectEstimate) -> bool {
        let by_clock = e.timing.stamps_ns[stage::ESTIMATOR_RECEIVED] >= self.sent_ns;
        if e.event_session == self.sent_session {
            by_clock && e.event_seq >= self.seq
        } else {
            by_clock
        }
    }

    /// Takes the reports that arrived; returns the first of `wanted` kind among them. Called
    /// by [`Self::wait_report`] alone, whose region it shares.
    fn drain_reports(&mut self, wanted: Option<LearnReportKind>) -> Option<LearnReport> {
        let mut found = None;
        while let Ok(Some(r)) = self.reports.receive() {
            let kind = LearnReportKind::from_u32(r.kind);
            if matches!(
                kind,
                Some(
                    LearnReportKind::TrialLearned
                        | LearnReportKind::TrialRejected
                        | LearnReportKind::Learned
                )
            ) {
                self.learned = r.trials_learned;
                self.rejected = r.trials_rejected;
            }
            if found.is_none() && kind.is_some() && kind == wanted {
                found = Some(*r);
            }
        }
        found
    }

    /// Waits up to `timeout` for a report of one of `kinds`. Ends with
    /// [`EstimatorRestarted`] when a restarted estimator acknowledges a frame meanwhile (it
    /// would never send the report).
    pub fn wait_report(
        &mut self,
        kinds: &[LearnReportKind],
        timeout: Duration,
    ) -> Result<LearnReport> {
        let _in_iceoryx2 = alloc_count::enter(alloc_count::Region::Iceoryx2);
        let start = std::time::Instant::now();
        loop {
            let mut acks = self.acks();
            take_estimates(&self.estimates, &mut acks);
            self.set_acks(acks);
            self.check_estimator()?;
            let mut found = None;
            for &k in kinds {
                if found.is_none() {
                    found = self.drain_reports(Some(k));
                }
            }
            if let Some(r) = found {
                return Ok(r);
            }
            let left = timeout.saturating_sub(start.elapsed());
            if left.is_zero() {
                bail!("no {kinds:?} report from the estimator within {timeout:?}");
            }
            let reports = &self.reports;
            match self
                .reports_waiter
                .wait_for(left.min(REPORT_WAIT_SLICE), || {
                    reports.has_samples().unwrap_or(false).then_some(())
                }) {
                WaitOutcome::Ready(()) | WaitOutcome::TimedOut => {}
                WaitOutcome::Shutdown => return Err(DriveError::Shutdown.into()),
            }
        }
    }
}

/// Takes the estimates that arrived: raises the acknowledged stamp to the newest one and
/// keeps that frame's estimate, with its receipt. An estimate of an estimator started
/// later than the one known marks a restart; one of an estimator started earlier (left in
/// the queue by one that died) is ignored.
fn take_estimates(estimates: &Subscriber<AgpIpc, ObjectEstimate, ()>, acks: &mut Acks) {
    while let Ok(Some(e)) = estimates.receive() {
        if e.estimator_start_ns < acks.estimator_start_ns {
            continue;
        }
        if e.estimator_start_ns > acks.estimator_start_ns {
            acks.restarted |= acks.estimator_start_ns != 0;
            acks.estimator_start_ns = e.estimator_start_ns;
        }
        let published = e.timing.stamps_ns[stage::FRAME_PUBLISHED];
        if published > acks.stamp {
            acks.stamp = published;
            acks.latest = Some((*e, monotonic_ns()));
            acks.newest = Some(*e);
        }
    }
}

/// Physics through the lockstep driver, each frame acknowledged by the estimator before it
/// is acted on, with the estimate of the latest frame at hand.
pub struct Ring {
    pub driver: LockstepDriver,
    pub link: EstimatorLink,
    /// The estimator's estimate of the driver's latest frame.
    estimate: ObjectEstimate,
}

impl Ring {
    /// The ring over `driver`, the estimator reached through `link`. Waits for the
    /// estimate of the driver's latest frame.
    pub fn new(driver: LockstepDriver, link: EstimatorLink) -> Result<Self> {
        let mut ring = Self {
            driver,
            link,
            estimate: ObjectEstimate::default(),
        };
        let first = ring.frame();
        ring.ack(&first)?;
        ring.catch_up()?;
        Ok(ring)
    }

    /// The latest frame.
    pub fn frame(&self) -> IrFrame {
        *self.driver.frame()
    }

    /// The estimator's estimate of the latest frame.
    pub fn estimate(&self) -> &ObjectEstimate {
        &self.estimate
    }

    /// Sends `event` about the latest frame.
    pub fn send(&mut self, event: LearnEvent) -> Result<()> {
        let f = self.frame();
        self.link.send(event, &f)
    }

    /// Sends wheel speeds (m/s) and returns the frame they make, acknowledged.
    pub fn step(&mut self, l: f64, r: f64) -> Result<IrFrame> {
        let _in_iceoryx2 = alloc_count::enter(alloc_count::Region::Iceoryx2);
        self.driver.send(l, r)?;
        let next = self.driver.frame().step + 1;
        self.next_frame(next)?;
        self.catch_up()
    }

    /// Puts the object and the robot at these poses; returns the frame of the reset world,
    /// acknowledged.
    pub fn reset(&mut self, object: Pose2, robot: Pose2) -> Result<IrFrame> {
        let _in_iceoryx2 = alloc_count::enter(alloc_count::Region::Iceoryx2);
        self.driver.send_reset(object, robot)?;
        let same = self.driver.frame().step;
        self.next_frame(same)?;
        self.catch_up()
    }

    /// Makes the latest frame one whose estimate is at hand and took in every event this
    /// planner sent: returns it. In lockstep the frame the last command made always is (the
    /// estimator drains the events sent before a command before it observes the frame the
    /// command makes, and acknowledges no later frame before the next command): nothing to
    /// do. In realtime physics steps on its own and the estimator follows it, so two cases
    /// need a later frame, taken without commanding (physics publishes one each period):
    /// - the estimator acknowledged a newer frame than the latest (the planner connected
    ///   while frames went by, or the estimator skipped one): the estimate of the latest
    ///   frame is not (or no longer) there to be had, and the planner would go on with an
    ///   older frame's estimate (at the start, `ObjectEstimate::default()`: a front gap of
    ///   0 and the robot at the origin);
    /// - the frame's estimate was made before the estimator took in the planner's last event
    ///   (physics published the frame while the planner was deciding, or while the event
    ///   crossed a bridge): it does not show the event's effect yet (a circling's match, a
    ///   push carried on). See [`EstimatorLink::took_in_last_event`].
    fn catch_up(&mut self) -> Result<IrFrame> {
        loop {
            let f = self.frame();
            let stamp = f.timing.stamps_ns[stage::FRAME_PUBLISHED];
            let paired = self.estimate.timing.stamps_ns[stage::FRAME_PUBLISHED] == stamp;
            if paired && self.link.took_in_last_event(&self.estimate) {
                return Ok(f);
            }
            if self.link.sent_ns > 0
                && monotonic_ns().saturating_sub(self.link.sent_ns)
                    > self.link.timeout.as_nanos() as u64
            {
                bail!(
                    "the estimator did not take in this planner's event {} (session {}) within {:?}: is the link to `agp-estimator` dropping events?",
                    self.link.seq,
                    self.link.sent_session,
                    self.link.timeout
                );
            }
            let newer = *self.driver.await_newer_frame()?;
            self.ack(&newer)?;
        }
    }

    /// The frame the command or reset just sent makes (of step `step`), once the estimator
    /// acknowledged it. Waits on the estimates alone. The frames are polled on each turn of
    /// the wait (the frame usually comes first, and a restarted physics shows there) but
    /// waited on only in the rare case of an acknowledgement that reached this planner
    /// before the frame did (physics preempted between its subscribers' deliveries).
    fn next_frame(&mut self, step: u64) -> Result<IrFrame> {
        let before = self.driver.frame().timing.stamps_ns[stage::FRAME_PUBLISHED];
        let driver = &mut self.driver;
        let link = &mut self.link;
        let estimates = &link.estimates;
        let mut acks = link.acks();
        let mut taken = None;
        let outcome = link.estimates_waiter.wait_for(link.timeout, || {
            take_estimates(estimates, &mut acks);
            if acks.restarted {
                return Some(Ok(()));
            }
            if taken.is_none() {
                match driver.take_frame() {
                    Ok(Some(f)) => taken = Some(f.timing.stamps_ns[stage::FRAME_PUBLISHED]),
                    Ok(None) => {}
                    Err(e) => return Some(Err(e)),
                }
            }
            // Acknowledged: the frame taken, or (not yet taken) one newer than `before`.
            (acks.stamp >= taken.unwrap_or(before + 1)).then_some(Ok(()))
        });
        link.set_acks(acks);
        if let Err(restarted) = link.check_estimator() {
            // The frame is taken all the same, so the next command answers it.
            if taken.is_none() && !matches!(outcome, WaitOutcome::Shutdown) {
                driver.await_frame()?;
            }
            return Err(restarted);
        }
        match outcome {
            WaitOutcome::Ready(Ok(())) => {}
            WaitOutcome::Ready(Err(e)) => return Err(e.into()),
            WaitOutcome::Shutdown => return Err(DriveError::Shutdown.into()),
            WaitOutcome::TimedOut if taken.is_some() => return Err(link.no_ack(step)),
            WaitOutcome::TimedOut => {
                return Err(DriveError::NoFrame {
                    step,
                    timeout: link.timeout,
                }
                .into());
            }
        }
        let f = match taken {
            Some(_) => *driver.frame(),
            None => *driver.await_frame()?,
        };
        self.ack(&f)?;
        Ok(f)
    }

    /// Waits for the estimator's acknowledgement of `f`, the driver's latest frame; the
    /// command answering it then carries the estimator's stamps and the estimate's receipt.
    fn ack(&mut self, f: &IrFrame) -> Result<()> {
        if let Some((estimate, received_ns)) = self.link.ack(f)? {
            self.driver.note_estimate(&estimate, received_ns);
        }
        if let Some(e) = self.link.newest
            && e.timing.stamps_ns[stage::FRAME_PUBLISHED]
                == f.timing.stamps_ns[stage::FRAME_PUBLISHED]
        {
            self.estimate = e;
        }
        Ok(())
    }
}
