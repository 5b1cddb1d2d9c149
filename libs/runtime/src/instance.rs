//! The one place that builds an instance's iceoryx2 config and opens its services, under the names of `agp_shared_types::ServiceNames`.

use std::path::{Path, PathBuf};
use std::time::Duration;

use iceoryx2::config::Config;
use iceoryx2::node::NodeCreationFailure;
use iceoryx2::prelude::*;
use iceoryx2::service::builder::event::EventOpenOrCreateError;
use iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenOrCreateError;
use iceoryx2::service::port_factory::subscriber::PortFactorySubscriber;
use iceoryx2::service::port_factory::{event, publish_subscribe};

use agp_shared_types::{
    ActiveEpoch, ControlRequest, ControlResponse, GRIDS_PER_ALPHA, Goal, GoalEnd, GradientGrid,
    GroundTruth, IrFrame, LearnEvent, LearnReport, MAX_GRID_ALPHAS, MotorCommand, ObjectEstimate,
    Reset, ServiceNames, Task,
};
use iceoryx2::service::port_factory::request_response;

use crate::AgpIpc;

pub use agp_shared_types::{InstanceNameError, MAX_INSTANCE_NAME_LEN, ROOT_ENV};

/// Why an instance's folder (the base folder of every instance's root, or the instance's
/// own root folder) could not be used.
#[derive(Debug, thiserror::Error)]
pub enum InstanceDirError {
    /// It is a link or a file, not a folder.
    #[error(
        "{} is not a folder (a symbolic link or another file); remove it, or set {ROOT_ENV} to a folder of your own",
        path.display()
    )]
    NotAFolder { path: PathBuf },
    /// Another user owns it.
    #[error(
        "{} belongs to uid {owner}, not to this user (uid {uid}); set {ROOT_ENV} to a folder of your own",
        path.display()
    )]
    NotOurs { path: PathBuf, owner: u32, uid: u32 },
    /// It could not be created, opened or tightened.
    #[error("cannot prepare the folder {}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// Creates `path` (mode 0700) unless it exists, then checks it without following a link:
/// a folder, ours, and tightened to 0700 if group or others have any access.
fn secure_dir(path: &Path) -> Result<(), InstanceDirError> {
    use std::os::unix::fs::{DirBuilderExt, MetadataExt, OpenOptionsExt, PermissionsExt};

    let io = |source| InstanceDirError::Io {
        path: path.to_path_buf(),
        source,
    };
    match std::fs::DirBuilder::new().mode(0o700).create(path) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
        Err(e) => return Err(io(e)),
    }
    let dir = match std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_DIRECTORY | libc::O_CLOEXEC)
        .open(path)
    {
        Ok(d) => d,
        Err(e) if matches!(e.raw_os_error(), Some(libc::ELOOP | libc::ENOTDIR)) => {
            return Err(InstanceDirError::NotAFolder {
                path: path.to_path_buf(),
            });
        }
        Err(e) => return Err(io(e)),
    };
    let meta = dir.metadata().map_err(io)?;
    // SAFETY: geteuid(2) has no preconditions and cannot fail.
    let uid = unsafe { libc::geteuid() };
    if meta.uid() != uid {
        return Err(InstanceDirError::NotOurs {
            path: path.to_path_buf(),
            owner: meta.uid(),
            uid,
        });
    }
    if meta.mode() & 0o077 != 0 {
        dir.set_permissions(std::fs::Permissions::from_mode(0o700))
            .map_err(io)?;
    }
    Ok(())
}

/// One running pipeline's iceoryx2 world: its name, its explicit config (prefix and root
/// folder of its own, nothing loaded from files) and the services it uses.
///
/// Every process of a pipeline builds the same `Instance` from the name the supervisor
/// passes it; two instances of different names share no file.
#[derive(Debug, Clone)]
pub struct Instance {
    name: String,
    config: Config,
    root: PathBuf,
}

/// Where instance roots live unless [`ROOT_ENV`] says otherwise.
const DEFAULT_ROOT_BASE: &str = "/tmp/agp";

/// The character that ends the instance name in every file name of an instance: one that
/// [`Instance::validate_name`] refuses and iceoryx2's `FileName` accepts.
const NAME_END: char = '.';

impl Instance {
    /// Builds the config of instance `name`: prefix `agp_<name>.`, root folder
    /// `<base>/<name>/` (base `/tmp/agp`, or `$AGP_IOX2_ROOT`). Nothing is created here:
    /// [`Instance::prepare_dirs`] makes the folders, and every node does it first.
    pub fn new(name: &str) -> Result<Self, InstanceNameError> {
        Self::validate_name(name)?;
        let base = std::env::var_os(ROOT_ENV)
            .map(PathBuf::from)
            .unwrap_or_else(|| PathBuf::from(DEFAULT_ROOT_BASE));
        let root = base.join(name);
        let mut config = Config::default();
        let mut root_str = root.to_string_lossy().into_owned();
        root_str.push('/');
        let iox_root = iceoryx2::prelude::Path::new(root_str.as_bytes())
            .expect("a validated instance name gives a valid root path");
        config.global.set_root_path(&iox_root);
        config.global.prefix = FileName::new(Self::prefix_of(name).as_bytes())
            .expect("a validated instance name gives a valid prefix");
        // A crashed process's resources are cleaned by the supervisor, which knows it died;
        // cleaning on open stays on as a second line of defence.
        config.global.creation_timeout = Duration::from_secs(2);
        Ok(Self {
            name: name.to_owned(),
            config,
            root,
        })
    }

    /// Checks a name without building anything ([`agp_shared_types::validate_instance_name`]).
    pub fn validate_name(name: &str) -> Result<(), InstanceNameError> {
        agp_shared_types::validate_instance_name(name)
    }

    /// The `.` ends the name: instance names cannot hold one (iceoryx2's file names can),
    /// so the files of `pc` (`agp_pc.…`) and of `pc_x` (`agp_pc_x.…`) never share a prefix,
    /// for our cleaning nor for iceoryx2's own listing of `/dev/shm`.
    fn prefix_of(name: &str) -> String {
        format!("agp_{name}{NAME_END}")
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    pub fn config(&self) -> &Config {
        &self.config
    }

    /// The prefix of every file of this instance in `/dev/shm`, ending in a character no
    /// instance name holds: a file starts with it exactly when it is this instance's.
    pub fn shm_prefix(&self) -> String {
        Self::prefix_of(&self.name)
    }

    /// The instance's iceoryx2 root folder.
    pub fn root_dir(&self) -> &Path {
        &self.root
    }

    /// Makes the base folder (`/tmp/agp` or `$AGP_IOX2_ROOT`) and the instance's root folder
    /// safe to use: each is created mode 0700 if missing, opened without following a link,
    /// refused if it is not a folder or belongs to another user, and tightened to 0700 if it
    /// is ours but open to group or others (a base created 0755 by an earlier version).
    pub fn prepare_dirs(&self) -> Result<(), InstanceDirError> {
        self.prepare_base()?;
        secure_dir(&self.root)
    }

    /// [`Instance::prepare_dirs`] for the base folder alone (where the instance locks live).
    pub fn prepare_base(&self) -> Result<(), InstanceDirError> {
        let base = self.root.parent().unwrap_or_else(|| Path::new("/"));
        if let Some(above) = base.parent()
            && !above.as_os_str().is_empty()
        {
            std::fs::create_dir_all(above).map_err(|source| InstanceDirError::Io {
                path: above.to_path_buf(),
                source,
            })?;
        }
        secure_dir(base)
    }

    /// Creates a node of this instance. With `handle_signals`, iceoryx2 installs its
    /// SIGINT/SIGTERM handler at the first wait, and the caller must poll for termination.
    pub fn node(
        &self,
        node_name: &str,
        handle_signals: bool,
    ) -> Result<Node<AgpIpc>, NodeCreationFailure> {
        self.node_of::<AgpIpc>(node_name, handle_signals)
    }

    /// [`Instance::node`] for another iceoryx2 service type (`bench-hop` measures
    /// iceoryx2's own `ipc::Service` beside [`AgpIpc`]). Processes of one pipeline all use
    /// [`AgpIpc`].
    ///
    /// The instance's folders are made safe first ([`Instance::prepare_dirs`]); a folder
    /// that cannot be is `InsufficientPermissions` (the supervisor calls `prepare_dirs`
    /// itself, before any child, to say why).
    pub fn node_of<S: iceoryx2::service::Service>(
        &self,
        node_name: &str,
        handle_signals: bool,
    ) -> Result<Node<S>, NodeCreationFailure> {
        self.prepare_dirs()
            .map_err(|_| NodeCreationFailure::InsufficientPermissions)?;
        let mut builder = NodeBuilder::new().config(&self.config);
        if let Ok(n) = NodeName::new(node_name) {
            builder = builder.name(&n);
        }
        builder
            .signal_handling_mode(if handle_signals {
                SignalHandlingMode::HandleTerminationRequests
            } else {
                SignalHandlingMode::Disabled
            })
            .create::<S>()
    }

    /// Every file this instance has on the machine: its `/dev/shm` entries and, if present,
    /// its root folder.
    pub fn files(&self) -> Vec<PathBuf> {
        let mut files = instance_files_in(Path::new("/dev/shm"), &self.shm_prefix());
        if self.root.symlink_metadata().is_ok() {
            files.push(self.root.clone());
        }
        files
    }

    /// Removes the instance's `/dev/shm` files and its root folder together. Call only when
    /// no process of the instance is alive. Returns how many entries were removed.
    pub fn remove_files(&self) -> std::io::Result<usize> {
        let mut removed = 0;
        for f in instance_files_in(Path::new("/dev/shm"), &self.shm_prefix()) {
            match std::fs::remove_file(&f) {
                Ok(()) => removed += 1,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => return Err(e),
            }
        }
        if self.root.symlink_metadata().is_ok() {
            // A client of the dead supervisor that gives up just now removes its node's
            // files under our feet: take what is left again.
            let mut tries = 0;
            loop {
                match std::fs::remove_dir_all(&self.root) {
                    Ok(()) => break,
                    Err(e) if e.kind() == std::io::ErrorKind::NotFound => break,
                    Err(e) if tries < 10 && e.kind() == std::io::ErrorKind::DirectoryNotEmpty => {
                        tries += 1;
                        std::thread::sleep(std::time::Duration::from_millis(20));
                    }
                    Err(e) => return Err(e),
                }
            }
            removed += 1;
        }
        Ok(removed)
    }

    pub fn ir_frames(&self, node: &Node<AgpIpc>) -> Result<Topic<IrFrame>, OpenError> {
        Topic::open(
            node,
            ServiceNames::IR_FRAMES,
            &ServiceNames::event_of(ServiceNames::IR_FRAMES),
            Qos::stream(),
        )
    }

    pub fn ground_truth(&self, node: &Node<AgpIpc>) -> Result<Topic<GroundTruth>, OpenError> {
        Topic::open(
            node,
            ServiceNames::GROUND_TRUTH,
            &ServiceNames::event_of(ServiceNames::GROUND_TRUTH),
            Qos::truth(),
        )
    }

    pub fn motor_commands(&self, node: &Node<AgpIpc>) -> Result<Topic<MotorCommand>, OpenError> {
        Topic::open(
            node,
            ServiceNames::MOTOR_COMMANDS,
            ServiceNames::PHYSICS_INBOX,
            Qos::commands(),
        )
    }

    pub fn resets(&self, node: &Node<AgpIpc>) -> Result<Topic<Reset>, OpenError> {
        Topic::open(
            node,
            ServiceNames::RESETS,
            ServiceNames::PHYSICS_INBOX,
            Qos::commands(),
        )
    }

    pub fn estimates(&self, node: &Node<AgpIpc>) -> Result<Topic<ObjectEstimate>, OpenError> {
        Topic::open(
            node,
            ServiceNames::ESTIMATES,
            &ServiceNames::event_of(ServiceNames::ESTIMATES),
            Qos::estimates(),
        )
    }

    pub fn grids(&self, node: &Node<AgpIpc>) -> Result<Topic<GradientGrid>, OpenError> {
        Topic::open(
            node,
            ServiceNames::GRIDS,
            &ServiceNames::event_of(ServiceNames::GRIDS),
            Qos::grids(),
        )
    }

    /// The goal of a live session (the supervisor publishes it; latched).
    pub fn goal(&self, node: &Node<AgpIpc>) -> Result<Topic<Goal>, OpenError> {
        Topic::open(
            node,
            ServiceNames::GOAL,
            &ServiceNames::event_of(ServiceNames::GOAL),
            Qos::latched(),
        )
    }

    pub fn task(&self, node: &Node<AgpIpc>) -> Result<Topic<Task>, OpenError> {
        Topic::open(
            node,
            ServiceNames::TASK,
            &ServiceNames::event_of(ServiceNames::TASK),
            Qos::latched(),
        )
    }
}

impl Instance {
    /// The active planner epoch (published by the supervisor, read by physics; a change
    /// wakes physics through its inbox).
    pub fn active_epoch(&self, node: &Node<AgpIpc>) -> Result<Topic<ActiveEpoch>, OpenError> {
        Topic::open(
            node,
            ServiceNames::ACTIVE_EPOCH,
            ServiceNames::PHYSICS_INBOX,
            Qos::epoch(),
        )
    }
}

impl Instance {
    /// Learning-protocol events; notifications go to the IR frames' event service.
    pub fn learn_events(&self, node: &Node<AgpIpc>) -> Result<Topic<LearnEvent>, OpenError> {
        Topic::open(
            node,
            ServiceNames::LEARN_EVENTS,
            &ServiceNames::event_of(ServiceNames::IR_FRAMES),
            Qos::learn(),
        )
    }

    /// Goals ended across a bridge ([`GoalEnd`]), with an event service of their own.
    pub fn goal_ends(&self, node: &Node<AgpIpc>) -> Result<Topic<GoalEnd>, OpenError> {
        Topic::open(
            node,
            ServiceNames::GOAL_ENDS,
            &ServiceNames::event_of(ServiceNames::GOAL_ENDS),
            Qos::learn(),
        )
    }

    /// The estimator's learning reports, with an event service of their own.
    pub fn learn_reports(&self, node: &Node<AgpIpc>) -> Result<Topic<LearnReport>, OpenError> {
        Topic::open(
            node,
            ServiceNames::LEARN_REPORTS,
            &ServiceNames::event_of(ServiceNames::LEARN_REPORTS),
            Qos::learn(),
        )
    }
}

impl Qos {
    /// Learning events and reports: every one matters, none is state a late reader needs
    /// (no history). The event service's limits match [`Qos::stream`]'s, since the events
    /// share the IR frames' event service.
    fn learn() -> Self {
        Self {
            history: 0,
            buffer: 64,
            max_publishers: 4,
            max_subscribers: 8,
            tap: 1024,
            borrowed: 2,
        }
    }
}

/// Files in `dir` whose name starts with `prefix`. With an instance's
/// [`Instance::shm_prefix`], which ends in a character no instance name holds, these are
/// exactly that instance's files.
pub fn instance_files_in(dir: &Path, prefix: &str) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut files: Vec<PathBuf> = entries
        .filter_map(Result::ok)
        .filter(|e| e.file_name().to_string_lossy().starts_with(prefix))
        .map(|e| e.path())
        .collect();
    files.sort();
    files
}

/// Quality of service of one topic. Every process opens a topic through [`Instance`], so
/// all agree on it (iceoryx2 refuses to open a service whose settings differ).
#[derive(Debug, Clone, Copy)]
struct Qos {
    history: usize,
    /// The buffer of the pipeline's own subscribers ([`Topic::subscriber`]).
    buffer: usize,
    max_publishers: usize,
    max_subscribers: usize,
    /// The deepest buffer a subscriber may ask for: a tap that must miss nothing at full
    /// lockstep speed, the recorder, asks for this much ([`TAP_DEPTH`]) on the topics it
    /// records; the pipeline's subscribers keep `buffer`.
    tap: usize,
    /// How many samples one subscriber may hold at once: 2 on every topic but the grids,
    /// where a reader may keep a whole set and read it in place (the Python package's
    /// gradient is numpy views over the held samples).
    borrowed: usize,
}

/// The buffer of a tap on a stream or command topic: 4096 messages, 6.4 s at 640 Hz, so a
/// recorder held off the cores for seconds still loses nothing. iceoryx2 sizes each
/// publisher's segment for its subscribers' largest possible buffers: frames
/// about 9 MB (8 subscribers of 272 bytes), estimates 8 MB, each command publisher 2 MB.
pub const TAP_DEPTH: usize = 4096;

impl Qos {
    /// A stream of state (frames, estimates): the latest matters; a new reader gets it at once.
    fn stream() -> Self {
        Self {
            history: 1,
            buffer: 4,
            max_publishers: 4,
            max_subscribers: 8,
            tap: TAP_DEPTH,
            borrowed: 2,
        }
    }

    /// Ground truth: the latest for the oracle, and every step for the judge, which reads
    /// it in batches (every millisecond when the machine is idle, but a busy two-core
    /// machine can hold it off for tens of milliseconds, thousands of steps at full
    /// lockstep speed): 8192 steps of room, 576 KiB per subscriber, 6 subscribers.
    fn truth() -> Self {
        Self {
            buffer: 8192,
            max_subscribers: 6,
            tap: 8192,
            ..Self::stream()
        }
    }

    /// Estimates: the latest for the planner, and every one for the judge, which counts
    /// them and reads them in batches as it reads ground truth: 1024 frames of room
    /// (1.6 s at 640 Hz), about 2 MB per publisher.
    fn estimates() -> Self {
        Self {
            buffer: 1024,
            ..Self::stream()
        }
    }

    /// Commands: every one must arrive in order. Room for old and new planner during a swap.
    fn commands() -> Self {
        Self {
            history: 0,
            buffer: 16,
            max_publishers: 6,
            max_subscribers: 4,
            tap: TAP_DEPTH,
            borrowed: 2,
        }
    }

    /// Gradient grids: a whole set ([`GRIDS_PER_ALPHA`] grids for each of up to
    /// [`MAX_GRID_ALPHAS`] alphas: 136 grids of 65,624 bytes, 8.9 MB) kept in history,
    /// so a late or restarted reader gets all of it, and fitting each reader's buffer, so a
    /// reader that drains only after the publication loses none.
    ///
    /// A reader may hold a whole set (`borrowed`), so it can read the gradient in place for
    /// as long as it plans on it. Each publisher preallocates `max_subscribers * (buffer +
    /// borrowed) + history + 2 loaned` samples: 1,226 grids, about 80 MB of shared memory.
    /// Subscribers: the planner, a hot-swapped one beside it, and one tool or test.
    fn grids() -> Self {
        let set = GRIDS_PER_ALPHA * MAX_GRID_ALPHAS;
        Self {
            history: set,
            buffer: set,
            max_publishers: 4,
            max_subscribers: 4,
            tap: set,
            borrowed: set,
        }
    }

    /// The active epoch: latched, and sharing physics's inbox event with the commands
    /// (an event service's limits must agree among its users).
    fn epoch() -> Self {
        Self {
            history: 1,
            buffer: 2,
            tap: 2,
            ..Self::commands()
        }
    }

    /// A value set once and read by whoever comes (the task).
    fn latched() -> Self {
        Self {
            history: 1,
            buffer: 2,
            max_publishers: 4,
            max_subscribers: 8,
            tap: 2,
            borrowed: 2,
        }
    }
}

/// Why a topic could not be opened.
#[derive(Debug)]
pub enum OpenError {
    ServiceName(String),
    PublishSubscribe(PublishSubscribeOpenOrCreateError),
    Event(EventOpenOrCreateError),
}

impl std::fmt::Display for OpenError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::ServiceName(n) => write!(f, "`{n}` is not a valid service name"),
            Self::PublishSubscribe(e) => write!(f, "cannot open the topic: {e:?}"),
            Self::Event(e) => write!(f, "cannot open the topic's event service: {e:?}"),
        }
    }
}

impl std::error::Error for OpenError {}

/// A publish-subscribe service and its paired event service.
pub struct Topic<T: std::fmt::Debug + ZeroCopySend + 'static> {
    pub data: publish_subscribe::PortFactory<AgpIpc, T, ()>,
    pub event: event::PortFactory<AgpIpc>,
    /// The buffer of the pipeline's subscribers on this topic.
    buffer: usize,
}

impl<T: std::fmt::Debug + ZeroCopySend + 'static> Topic<T> {
    /// A subscriber of the pipeline's own: its buffer is the topic's (a stream keeps the
    /// latest few, commands their 16). `data.subscriber_builder()` without a buffer size
    /// gives a tap the deepest buffer the service allows (the recorder's).
    pub fn subscriber(&self) -> PortFactorySubscriber<'_, AgpIpc, T, ()> {
        self.data.subscriber_builder().buffer_size(self.buffer)
    }
}

impl<T: std::fmt::Debug + ZeroCopySend + 'static> Topic<T> {
    fn open(node: &Node<AgpIpc>, name: &str, event_str: &str, qos: Qos) -> Result<Self, OpenError> {
        let data_name: ServiceName = name
            .try_into()
            .map_err(|_| OpenError::ServiceName(name.to_owned()))?;
        let event_name: ServiceName = event_str
            .try_into()
            .map_err(|_| OpenError::ServiceName(event_str.to_owned()))?;

        // After a crash a service can answer "corrupted" for a moment, while its creator's
        // files are half removed: retry a few times before giving up.
        let mut attempt = 0;
        let data = loop {
            match node
                .service_builder(&data_name)
                .publish_subscribe::<T>()
                .history_size(qos.history)
                .subscriber_max_buffer_size(qos.buffer.max(qos.history).max(qos.tap))
                .subscriber_max_borrowed_samples(qos.borrowed)
                .max_publishers(qos.max_publishers)
                .max_subscribers(qos.max_subscribers)
                .max_nodes(16)
                .open_or_create()
            {
                Ok(s) => break s,
                Err(e) if attempt < 20 && is_transient_ps(&e) => {
                    attempt += 1;
                    std::thread::sleep(Duration::from_millis(10));
                }
                Err(e) => return Err(OpenError::PublishSubscribe(e)),
            }
        };
        let mut attempt = 0;
        let event = loop {
            match node
                .service_builder(&event_name)
                .event()
                .event_id_max_value(crate::EVENT_ID_MAX_VALUE)
                .max_notifiers(16)
                .max_listeners(qos.max_subscribers)
                .max_nodes(16)
                .open_or_create()
            {
                Ok(s) => break s,
                Err(e) if attempt < 20 && is_transient_ev(&e) => {
                    attempt += 1;
                    std::thread::sleep(Duration::from_millis(10));
                }
                Err(e) => return Err(OpenError::Event(e)),
            }
        };
        Ok(Self {
            data,
            event,
            buffer: qos.buffer.max(qos.history),
        })
    }
}

fn is_transient_ps(e: &PublishSubscribeOpenOrCreateError) -> bool {
    use iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenError as O;
    matches!(
        e,
        PublishSubscribeOpenOrCreateError::SystemInFlux
            | PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
                O::ServiceInCorruptedState | O::IsMarkedForDestruction | O::HangsInCreation
            )
    )
}

fn is_transient_ev(e: &EventOpenOrCreateError) -> bool {
    use iceoryx2::service::builder::event::EventOpenError as O;
    matches!(
        e,
        EventOpenOrCreateError::SystemInFlux
            | EventOpenOrCreateError::EventOpenError(
                O::ServiceInCorruptedState | O::IsMarkedForDestruction | O::HangsInCreation
            )
    )
}

/// The control service of an instance.
pub type ControlService =
    request_response::PortFactory<AgpIpc, ControlRequest, (), ControlResponse, ()>;

/// Why [`Instance::running`] found no running instance of that name.
#[derive(Debug, thiserror::Error)]
pub enum RunningInstanceError {
    #[error("bad instance name `{name}`: {why}")]
    BadName {
        name: String,
        why: InstanceNameError,
    },
    #[error("no supervisor runs instance `{0}` (start it with `agp up`)")]
    NotRunning(String),
}

/// Why the control service could not be reached.
#[derive(Debug, thiserror::Error)]
pub enum ControlOpenError {
    #[error("the control service name is invalid")]
    Name,
    #[error("cannot create the control service: {0}")]
    Create(String),
    #[error("no supervisor answers on instance `{0}`")]
    NotRunning(String),
}

impl Instance {
    /// Creates the control service (the supervisor, once per run).
    pub fn create_control(&self, node: &Node<AgpIpc>) -> Result<ControlService, ControlOpenError> {
        let name: ServiceName = ServiceNames::CONTROL
            .try_into()
            .map_err(|_| ControlOpenError::Name)?;
        node.service_builder(&name)
            .request_response::<ControlRequest, ControlResponse>()
            .max_clients(8)
            .max_servers(1)
            .max_nodes(16)
            .create()
            .map_err(|e| ControlOpenError::Create(format!("{e:?}")))
    }

    /// The instance named `name`, which a supervisor must run (its control service is up):
    /// what a client of a running instance (`agp record`, a bridge) opens first.
    pub fn running(name: &str) -> Result<Self, RunningInstanceError> {
        let instance = Self::new(name).map_err(|why| RunningInstanceError::BadName {
            name: name.to_owned(),
            why,
        })?;
        if !instance.control_exists() {
            return Err(RunningInstanceError::NotRunning(name.to_owned()));
        }
        Ok(instance)
    }

    /// Whether the supervisor has created the control service, asked without a node: a
    /// client that made one before the supervisor has cleaned the instance's leftovers
    /// would be a stranger it must wait for.
    pub fn control_exists(&self) -> bool {
        let Ok(name) = ServiceName::new(ServiceNames::CONTROL) else {
            return false;
        };
        AgpIpc::does_exist(&name, self.config(), MessagingPattern::RequestResponse).unwrap_or(false)
    }

    /// Opens the control service of a running supervisor (a client).
    pub fn open_control(&self, node: &Node<AgpIpc>) -> Result<ControlService, ControlOpenError> {
        let name: ServiceName = ServiceNames::CONTROL
            .try_into()
            .map_err(|_| ControlOpenError::Name)?;
        node.service_builder(&name)
            .request_response::<ControlRequest, ControlResponse>()
            .open()
            .map_err(|_| ControlOpenError::NotRunning(self.name().to_owned()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_instance_no_supervisor_runs_is_not_running_and_a_bad_name_is_refused() {
        let name = format!("not-running-{}", std::process::id());
        assert!(matches!(
            Instance::running(&name),
            Err(RunningInstanceError::NotRunning(n)) if n == name
        ));
        assert!(matches!(
            Instance::running("Not.A.Name"),
            Err(RunningInstanceError::BadName { .. })
        ));
    }
}
