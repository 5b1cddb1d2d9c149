//! The iceoryx2 side of a bridge: one typed port per topic behind an untyped face, so the
//! forwarding loops handle every topic alike, as bytes.

use core::mem::size_of;

use agp_runtime::{AgpIpc, Instance, OpenError, Topic};
use agp_shared_types::{
    Goal, GoalEnd, GradientGrid, IrFrame, LearnEvent, LearnReport, MotorCommand, ObjectEstimate,
    Reset, Task,
};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::{Node, ZeroCopySend};

use crate::route::BridgedTopic;

/// A payload whose bytes are all initialised (no implicit padding) and of which any bit
/// pattern of its size is a valid value: `#[repr(C)]` integers, floats and arrays of them,
/// padding spelled out as `_pad` fields.
///
/// # Safety
///
/// An implementer promises the above: the bridge reads a value's bytes and writes any bytes
/// of the right length into a loaned sample as a value.
pub(crate) unsafe trait Wire: std::fmt::Debug + ZeroCopySend + 'static {}

// Each payload below is `agp_recording::Plain` (`#[repr(C)]` integers and floats, padding
// spelled out; agp-recording's layout test checks that every byte belongs to a field), or,
// for the grid, a `GridHeader` (Plain) followed by an array of f32: the promise `Wire` asks.
// SAFETY: `IrFrame` is `agp_recording::Plain`: every byte a field, any bits a value.
unsafe impl Wire for IrFrame {}
// SAFETY: `ObjectEstimate` is `agp_recording::Plain`: every byte a field, any bits a value.
unsafe impl Wire for ObjectEstimate {}
// SAFETY: a `GridHeader` (Plain) then `[f32; N]`: every byte a field, any bits a value.
unsafe impl Wire for GradientGrid {}
// SAFETY: `LearnReport` is `agp_recording::Plain`: every byte a field, any bits a value.
unsafe impl Wire for LearnReport {}
// SAFETY: `LearnEvent` is `agp_recording::Plain`: every byte a field, any bits a value.
unsafe impl Wire for LearnEvent {}
// SAFETY: `Task` is `agp_recording::Plain`: every byte a field, any bits a value.
unsafe impl Wire for Task {}
// SAFETY: `Reset` is `agp_recording::Plain`: every byte a field, any bits a value.
unsafe impl Wire for Reset {}
// SAFETY: `MotorCommand` is `agp_recording::Plain`: every byte a field, any bits a value.
unsafe impl Wire for MotorCommand {}
// SAFETY: `Goal` is `agp_recording::Plain`: every byte a field, any bits a value.
unsafe impl Wire for Goal {}
// SAFETY: `GoalEnd` is `agp_recording::Plain`: every byte a field, any bits a value.
unsafe impl Wire for GoalEnd {}

/// How the receiving end changes the fields that belong to its own instance before it
/// republishes a message: the epoch and token of commands and resets (the robot side's
/// physics applies only its own supervisor's epoch and token), the active epoch frames
/// report (the planner side's supervisor owns its epochs).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Restamp {
    pub epoch: u64,
    pub token: u64,
}

/// The epoch and token a command or reset carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Auth {
    pub epoch: u64,
    pub token: u64,
}

/// What [`OutPort::drain`] hands each sample to: its bytes and, for commands and resets,
/// their [`Auth`].
pub(crate) type Each<'a> = dyn FnMut(&[u8], Option<Auth>) + 'a;

/// Sends each sample waiting on a topic of this end as bytes.
pub(crate) trait OutPort {
    /// Hands every waiting sample to `each`; returns how many.
    fn drain(&mut self, each: &mut Each<'_>) -> Result<usize, String>;
}

/// Republishes bytes from the far end on a topic of this end.
pub(crate) trait InPort {
    /// Writes `bytes` (checked: the payload's size) into a loaned sample, restamps it,
    /// sends it and notifies the topic's event service.
    fn publish(&mut self, bytes: &[u8], restamp: Restamp) -> Result<(), String>;

    /// Hands the publisher's history to subscribers that came since it last sent: a
    /// planner swapped in long after the grid set crossed gets it so.
    fn update_connections(&self);
}

struct Out<T: Wire> {
    sub: Subscriber<AgpIpc, T, ()>,
    auth: fn(&T) -> Option<Auth>,
}

impl<T: Wire> OutPort for Out<T> {
    fn drain(&mut self, each: &mut Each<'_>) -> Result<usize, String> {
        let mut n = 0;
        loop {
            match self.sub.receive() {
                Ok(Some(s)) => {
                    let p: &T = s.payload();
                    // SAFETY: `T: Wire`: every byte of the value is initialised.
                    let bytes = unsafe {
                        std::slice::from_raw_parts((p as *const T).cast::<u8>(), size_of::<T>())
                    };
                    each(bytes, (self.auth)(p));
                    n += 1;
                }
                Ok(None) => return Ok(n),
                Err(e) => return Err(format!("{e:?}")),
            }
        }
    }
}

struct In<T: Wire> {
    publisher: Publisher<AgpIpc, T, ()>,
    notifier: Notifier<AgpIpc>,
    restamp: fn(&mut T, Restamp),
}

impl<T: Wire> InPort for In<T> {
    fn publish(&mut self, bytes: &[u8], restamp: Restamp) -> Result<(), String> {
        assert_eq!(
            bytes.len(),
            size_of::<T>(),
            "checked against the topic's size"
        );
        let mut sample = self
            .publisher
            .loan_uninit()
            .map_err(|e| format!("loan: {e:?}"))?;
        // SAFETY: the sample holds room for one `T`, `bytes` is exactly that long, and
        // `T: Wire` makes any bytes a valid `T`: the payload is initialised whole, once,
        // in shared memory (a grid is never copied on the way).
        let mut sample = unsafe {
            std::ptr::copy_nonoverlapping(
                bytes.as_ptr(),
                sample.payload_mut().as_mut_ptr().cast::<u8>(),
                bytes.len(),
            );
            sample.assume_init()
        };
        (self.restamp)(sample.payload_mut(), restamp);
        sample.send().map_err(|e| format!("send: {e:?}"))?;
        let _ = self.notifier.notify();
        Ok(())
    }

    fn update_connections(&self) {
        if self.publisher.update_connections().is_ok() {
            // A new subscriber may wait for this history on the topic's event.
            let _ = self.notifier.notify();
        }
    }
}

fn no_auth<T>(_: &T) -> Option<Auth> {
    None
}

fn keep<T>(_: &mut T, _: Restamp) {}

type Opener<T> = fn(&Instance, &Node<AgpIpc>) -> Result<Topic<T>, OpenError>;

fn open_out<T: Wire>(
    instance: &Instance,
    node: &Node<AgpIpc>,
    open: Opener<T>,
    auth: fn(&T) -> Option<Auth>,
) -> Result<(Box<dyn OutPort>, Listener<AgpIpc>), String> {
    let topic = open(instance, node).map_err(|e| e.to_string())?;
    // No buffer size: the deepest the service allows, so a bridge held off the cores for a
    // moment loses no frame (iceoryx2 would overwrite the oldest).
    let sub = topic
        .data
        .subscriber_builder()
        .create()
        .map_err(|e| format!("subscriber: {e:?}"))?;
    let listener = topic
        .event
        .listener_builder()
        .create()
        .map_err(|e| format!("listener: {e:?}"))?;
    Ok((Box::new(Out { sub, auth }), listener))
}

fn open_in<T: Wire>(
    instance: &Instance,
    node: &Node<AgpIpc>,
    open: Opener<T>,
    restamp: fn(&mut T, Restamp),
) -> Result<Box<dyn InPort>, String> {
    let topic = open(instance, node).map_err(|e| e.to_string())?;
    let publisher = topic
        .data
        .publisher_builder()
        .create()
        .map_err(|e| format!("publisher: {e:?}"))?;
    let notifier = topic
        .event
        .notifier_builder()
        .create()
        .map_err(|e| format!("notifier: {e:?}"))?;
    Ok(Box::new(In {
        publisher,
        notifier,
        restamp,
    }))
}

/// The subscriber (and the listener of its event service) of a topic this end sends.
pub(crate) fn out_port(
    instance: &Instance,
    node: &Node<AgpIpc>,
    topic: &BridgedTopic,
) -> Result<(Box<dyn OutPort>, Listener<AgpIpc>), String> {
    match topic.name {
        "grids" => open_out(instance, node, Instance::grids, no_auth),
        "ir_frames" => open_out(instance, node, Instance::ir_frames, no_auth),
        "estimates" => open_out(instance, node, Instance::estimates, no_auth),
        "learn_reports" => open_out(instance, node, Instance::learn_reports, no_auth),
        "learn_events" => open_out(instance, node, Instance::learn_events, no_auth),
        "task" => open_out(instance, node, Instance::task, no_auth),
        "goal" => open_out(instance, node, Instance::goal, no_auth),
        "goal_ends" => open_out(instance, node, Instance::goal_ends, no_auth),
        "resets" => open_out(instance, node, Instance::resets, |r: &Reset| {
            Some(Auth {
                epoch: r.epoch,
                token: r.token,
            })
        }),
        "motor_commands" => open_out(
            instance,
            node,
            Instance::motor_commands,
            |c: &MotorCommand| {
                Some(Auth {
                    epoch: c.epoch,
                    token: c.token,
                })
            },
        ),
        other => Err(format!("`{other}` is not a bridged topic")),
    }
}

/// The publisher (and notifier) of a topic this end receives.
pub(crate) fn in_port(
    instance: &Instance,
    node: &Node<AgpIpc>,
    topic: &BridgedTopic,
) -> Result<Box<dyn InPort>, String> {
    match topic.name {
        "grids" => open_in(instance, node, Instance::grids, keep),
        "ir_frames" => open_in(instance, node, Instance::ir_frames, |f: &mut IrFrame, r| {
            f.active_epoch = r.epoch;
        }),
        "estimates" => open_in(instance, node, Instance::estimates, keep),
        "learn_reports" => open_in(instance, node, Instance::learn_reports, keep),
        "learn_events" => open_in(instance, node, Instance::learn_events, keep),
        "task" => open_in(instance, node, Instance::task, keep),
        "goal" => open_in(instance, node, Instance::goal, keep),
        "goal_ends" => open_in(instance, node, Instance::goal_ends, keep),
        "resets" => open_in(instance, node, Instance::resets, |x: &mut Reset, r| {
            x.epoch = r.epoch;
            x.token = r.token;
        }),
        "motor_commands" => open_in(
            instance,
            node,
            Instance::motor_commands,
            |c: &mut MotorCommand, r| {
                c.epoch = r.epoch;
                c.token = r.token;
            },
        ),
        other => Err(format!("`{other}` is not a bridged topic")),
    }
}
