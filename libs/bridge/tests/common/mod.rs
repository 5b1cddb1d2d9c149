//! What the bridge's tests share: an end's config, an end run in a thread, an instance with
//! the control service a supervisor would hold.

use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::Duration;

use agp_bridge::{BridgeConfig, BridgeError, BridgeReport, Endpoint, Side, all_topics, run_bridge};
use agp_runtime::{AgpIpc, Instance, WaitStrategy};
use iceoryx2::prelude::Node;

/// Safety net of every wait; the checks never depend on it.
pub const TIMEOUT: Duration = Duration::from_secs(30);

/// An end carrying every topic on `link`, blocking while idle.
pub fn config(side: Side, endpoint: Endpoint, link: &str, epoch: u64, token: u64) -> BridgeConfig {
    BridgeConfig {
        side,
        endpoint,
        tls: None,
        topics: all_topics(),
        link: link.to_owned(),
        epoch,
        token,
        key: None,
        node_name: format!("bridge-{}", side.name()),
        wait: WaitStrategy::Block,
        far_timeout: agp_bridge::FAR_TIMEOUT,
        redeliver_command: false,
    }
}

/// Runs one end in a thread; returns once its ports are open.
pub fn start(
    instance: &Instance,
    config: BridgeConfig,
) -> JoinHandle<Result<BridgeReport, BridgeError>> {
    let instance = instance.clone();
    let (tx, rx) = mpsc::channel();
    let handle = std::thread::spawn(move || {
        run_bridge(&instance, &config, || {
            let _ = tx.send(());
        })
    });
    rx.recv_timeout(TIMEOUT).expect("the bridge's ports open");
    handle
}

/// An instance with the control service a supervisor would hold (the bridge stops when it
/// is gone).
pub fn instance(name: &str) -> (Instance, Node<AgpIpc>, agp_runtime::ControlService) {
    let instance = Instance::new(name).expect("a valid name");
    let _ = instance.remove_files();
    let node = instance.node("test", false).expect("node");
    let control = instance.create_control(&node).expect("control service");
    (instance, node, control)
}
