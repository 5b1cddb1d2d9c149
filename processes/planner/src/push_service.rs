//! `--skills`: the push-level service. A push-level planner of another process (the `agp`
//! Python package's `PushPlanner`, whose `agp.run` starts this planner as its child with
//! the same `AGP_*` environment) chooses each push; this process carries it out with the
//! planning library's skills: travel round the object to the push's start, the push, the
//! circling that re-estimates the object, Algorithm 5's rules of when to circle.
//!
//! Before each push it publishes a [`PushRequest`] on `agp/push_requests` and waits for the
//! [`PushChoice`] of the same seq and epoch on `agp/push_choices`. In lockstep it waits
//! without stepping (physics waits too, so a run stays reproducible); on the realtime clock
//! it keeps the ring going with the wheels stopped meanwhile.

use std::time::{Duration, Instant};

use agp_planning::{ExternalPush, PushQuery};
use agp_runtime::{AgpIpc, Instance, shutdown_requested};
use agp_shared_types::{
    PUSH_CHOICES, PUSH_REQUESTS, Pose2, PushChoice, PushChoiceKind, PushRequest,
};
use anyhow::{Result, anyhow};
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::{Node, ServiceName};

/// Both sides open the two topics with these limits (iceoryx2 opens a service only for a
/// requester that asks no more than its creator gave).
const HISTORY: usize = 1;
const BUFFER: usize = 4;
const MAX_PORTS: usize = 4;

/// How long a push-level planner may take to answer before the run fails.
pub const ANSWER_TIMEOUT: Duration = Duration::from_secs(60);

pub struct PushService {
    requests: Publisher<AgpIpc, PushRequest, ()>,
    choices: Subscriber<AgpIpc, PushChoice, ()>,
    _node: Node<AgpIpc>,
    epoch: u64,
    seq: u64,
}

/// Whether the answer to the last question came.
pub enum Pending {
    Answer(ExternalPush),
    Waiting,
}

impl PushService {
    pub fn open(instance: &Instance, epoch: u64) -> Result<Self> {
        let node = instance
            .node(&format!("planner-skills-{epoch}"), false)
            .map_err(|e| anyhow!("cannot create the skills node: {e:?}"))?;
        let requests = Self::topic::<PushRequest>(&node, PUSH_REQUESTS)?
            .publisher_builder()
            .create()
            .map_err(|e| anyhow!("cannot publish push requests: {e:?}"))?;
        let choices = Self::topic::<PushChoice>(&node, PUSH_CHOICES)?
            .subscriber_builder()
            .buffer_size(BUFFER)
            .create()
            .map_err(|e| anyhow!("cannot subscribe to push choices: {e:?}"))?;
        Ok(Self {
            requests,
            choices,
            _node: node,
            epoch,
            seq: 0,
        })
    }

    fn topic<T: std::fmt::Debug + iceoryx2::prelude::ZeroCopySend + 'static>(
        node: &Node<AgpIpc>,
        name: &str,
    ) -> Result<iceoryx2::service::port_factory::publish_subscribe::PortFactory<AgpIpc, T, ()>>
    {
        let service: ServiceName = name
            .try_into()
            .map_err(|e| anyhow!("bad service name {name}: {e:?}"))?;
        node.service_builder(&service)
            .publish_subscribe::<T>()
            .history_size(HISTORY)
            .subscriber_max_buffer_size(BUFFER)
            .max_publishers(MAX_PORTS)
            .max_subscribers(MAX_PORTS)
            .max_nodes(16)
            .open_or_create()
            .map_err(|e| anyhow!("cannot open {name}: {e:?}"))
    }

    /// Publishes the question for `query`.
    pub fn ask(
        &mut self,
        query: &PushQuery,
        goal_id: u64,
        robot: Pose2,
        sim_time_s: f64,
    ) -> Result<()> {
        self.seq += 1;
        let request = PushRequest {
            seq: self.seq,
            epoch: self.epoch,
            goal_id,
            object: query.object,
            sigma_xy: query.error_m,
            sigma_theta: query.error_rad,
            goal: query.goal,
            tolerance_m: query.tolerance_m,
            tolerance_rad: query.tolerance_rad,
            robot,
            start_radius_m: query.start_radius_m,
            sim_time_s,
            pushes: query.pushes,
            pushes_since_estimate: query.pushes_since_estimate,
            symmetry_order: query.symmetry_order,
            full_only: u32::from(query.full_only),
        };
        let sample = self
            .requests
            .loan_uninit()
            .map_err(|e| anyhow!("cannot loan a push request: {e:?}"))?;
        sample
            .write_payload(request)
            .send()
            .map_err(|e| anyhow!("cannot send a push request: {e:?}"))?;
        Ok(())
    }

    /// The answer to the last question, if it came.
    pub fn poll(&mut self) -> Result<Pending> {
        while let Ok(Some(c)) = self.choices.receive() {
            if c.epoch != self.epoch || c.seq != self.seq {
                continue;
            }
            return Ok(Pending::Answer(match PushChoiceKind::from_u32(c.kind) {
                Some(PushChoiceKind::Push) => ExternalPush::Push {
                    contact_deg: c.contact_deg,
                    alpha_deg: c.alpha_deg,
                    length_m: c.length_mm * 1e-3,
                },
                Some(PushChoiceKind::Done) => ExternalPush::Done,
                Some(PushChoiceKind::GiveUp) => ExternalPush::GiveUp,
                None => return Err(anyhow!("a push choice of unknown kind {}", c.kind)),
            }));
        }
        Ok(Pending::Waiting)
    }

    /// Waits (sleeping) for the answer to the last question; `None` on shutdown.
    pub fn wait(&mut self) -> Result<Option<ExternalPush>> {
        let start = Instant::now();
        loop {
            if let Pending::Answer(a) = self.poll()? {
                return Ok(Some(a));
            }
            if shutdown_requested() {
                return Ok(None);
            }
            if start.elapsed() > ANSWER_TIMEOUT {
                return Err(anyhow!(
                    "the push-level planner did not answer push request {} within {ANSWER_TIMEOUT:?}",
                    self.seq
                ));
            }
            std::thread::sleep(Duration::from_micros(200));
        }
    }
}
