//! Opening the stack's iceoryx2 services with the schema-version handshake.
//!
//! Every service is opened (or created) with the attribute
//! `schema_version = SCHEMA_VERSION`. A peer built from another version
//! created the service with another value, so opening fails, and the error
//! says which versions met. Every process opens a service with the same
//! settings (from [`ServiceSettings::of`]), so creator and opener agree
//! whichever starts first.

use crate::{Message, SCHEMA_VERSION, service_name};
use iceoryx2::node::NodeState;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::attribute::{AttributeKey, AttributeValue};
use iceoryx2::service::builder::publish_subscribe::{
    PublishSubscribeOpenError, PublishSubscribeOpenOrCreateError,
};
use iceoryx2_log::Log;

/// The service attribute that carries the schema version.
pub const SCHEMA_ATTRIBUTE: &str = "vision_touch.schema_version";

/// A publisher of message `T`.
pub type Pub<T> = Publisher<ipc::Service, T, ()>;
/// A subscriber of message `T`.
pub type Sub<T> = Subscriber<ipc::Service, T, ()>;
/// A node of the stack.
pub type StackNode = Node<ipc::Service>;

/// Why a service could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum TransportError {
    /// The peer that created the service was built from another schema.
    #[error(
        "service '{service}' speaks schema version {theirs} but this process was built with \
         schema version {ours}: rebuild both from the same shared-mem-schema"
    )]
    SchemaMismatch {
        /// Service name.
        service: String,
        /// Our [`SCHEMA_VERSION`].
        ours: u32,
        /// The version the service was created with (as text; "none" when
        /// it has no version attribute).
        theirs: String,
    },
    /// A topic with one owner already has its publisher: a second process
    /// claims to be the hardware or the controller.
    #[error(
        "service '{service}' already has its publisher (it allows {max}): is another {owner} \
         running on this namespace?"
    )]
    PublisherTaken {
        /// Service name.
        service: String,
        /// Publishers the service allows.
        max: usize,
        /// Who owns the topic.
        owner: &'static str,
    },
    /// The service exists with other capacities than this build's (created
    /// by a process that did not use [`ServiceSettings::of`]).
    #[error(
        "service '{service}' allows {found} {what}, this stack requires {expected}: it was \
         created by a foreign process; stop it and remove the service"
    )]
    ForeignSettings {
        /// Service name.
        service: String,
        /// Which capacity: "publishers" or "subscribers".
        what: &'static str,
        /// What the existing service allows.
        found: usize,
        /// What [`ServiceSettings::of`] asks for.
        expected: usize,
    },
    /// A topic's subscribers are all taken: only its intended readers may
    /// subscribe ([`ServiceSettings::subscribers`]).
    #[error("service '{service}' already has all the subscribers it allows ({max}): {readers}")]
    SubscribersTaken {
        /// Service name.
        service: String,
        /// Subscribers the service allows.
        max: usize,
        /// Who they are meant to be.
        readers: &'static str,
    },
    /// `VISION_TOUCH_IPC_ROOT` does not name a directory iceoryx2 can use.
    #[error("{0}")]
    IpcRoot(String),
    /// Any other iceoryx2 failure.
    #[error("iceoryx2: {what} '{service}': {detail}")]
    Ipc {
        /// Service or node name.
        service: String,
        /// What was being done.
        what: &'static str,
        /// iceoryx2's error.
        detail: String,
    },
}

/// Per-topic capacities. The same for every opener of a topic.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ServiceSettings {
    /// Samples a subscriber may queue.
    pub buffer: usize,
    /// Publishers allowed at once: one where the topic has one owner (the
    /// hardware's state and camera, the controller's commands and frames,
    /// the simulator's reports), so that no other process of the same user
    /// can speak for the robot or the controller.
    pub publishers: usize,
    /// Subscribers allowed at once: on the 1 kHz loop's own streams with
    /// the hardware (its state and torque command) the one reader meant
    /// for it and one observer (a monitor, a test), so that no further
    /// process can join them and make the real-time thread set up its
    /// connection ([`readers_of`]); elsewhere 8.
    pub subscribers: usize,
}

impl ServiceSettings {
    /// The settings of a message type's topic. Small fast streams get deep
    /// queues so a 20 Hz reader loses nothing of the 1 kHz streams; the
    /// camera keeps only a few frames (each is ~460 kB).
    pub fn of<T: Message>() -> Self {
        let buffer = match T::TOPIC {
            crate::topics::SENSOR => 1024,
            crate::topics::CAMERA => 4,
            crate::topics::HARDWARE_STATE | crate::topics::TORQUE_COMMAND => 8,
            crate::topics::EPISODE => 64,
            _ => 16,
        };
        Self {
            buffer,
            publishers: if owner_of(T::TOPIC).is_some() { 1 } else { 4 },
            subscribers: if readers_of(T::TOPIC).is_some() { 2 } else { 8 },
        }
    }
}

/// Who may subscribe to `topic`, for the topics whose readers are limited
/// ([`ServiceSettings::subscribers`]; `None`: any of 8).
pub fn readers_of(topic: &str) -> Option<&'static str> {
    use crate::topics::*;
    match topic {
        HARDWARE_STATE => Some("the controller and one observer"),
        TORQUE_COMMAND => Some("the hardware and one observer"),
        _ => None,
    }
}

/// The one process that publishes `topic`, for the topics that have one
/// (`None`: several may, as policy actions and simulator commands from the
/// learner, tools and tests).
pub fn owner_of(topic: &str) -> Option<&'static str> {
    use crate::topics::*;
    match topic {
        HARDWARE_STATE | CAMERA | EPISODE => Some("hardware (hw-sim)"),
        TORQUE_COMMAND | SENSOR | STATUS => Some("rt-controller"),
        _ => None,
    }
}

fn ipc_err(service: &str, what: &'static str, e: impl core::fmt::Debug) -> TransportError {
    TransportError::Ipc {
        service: service.to_string(),
        what,
        detail: format!("{e:?}"),
    }
}

/// The longest line an iceoryx2 message becomes, in characters.
pub const MAX_LOG_LINE: usize = 200;

/// iceoryx2's messages as one short line each on stderr. Its own console
/// logger prints the `Debug` form of the object that logged above each
/// message: on a dead node's clean-up, kilobytes of service configuration.
struct OneLineLogger;

impl Log for OneLineLogger {
    fn log(&self, level: LogLevel, _origin: core::fmt::Arguments, message: core::fmt::Arguments) {
        use std::io::Write;
        // A closed stderr is no reason to stop.
        let _ = writeln!(
            std::io::stderr().lock(),
            "{}",
            log_line(level, &message.to_string())
        );
    }
}

/// The line an iceoryx2 message becomes: its level and text, whitespace
/// runs (newlines included) collapsed to one space, cut to
/// [`MAX_LOG_LINE`] characters.
pub fn log_line(level: LogLevel, message: &str) -> String {
    let level = match level {
        LogLevel::Trace => "trace",
        LogLevel::Debug => "debug",
        LogLevel::Info => "info",
        LogLevel::Warn => "warning",
        LogLevel::Error => "error",
        LogLevel::Fatal => "fatal",
    };
    let mut line = format!("iceoryx2 {level}:");
    for word in message.split_whitespace() {
        line.push(' ');
        line.push_str(word);
    }
    if line.chars().count() > MAX_LOG_LINE {
        line = line.chars().take(MAX_LOG_LINE - 1).collect();
        line.push('…');
    }
    line
}

/// Makes iceoryx2's logging fit for users: errors only, one short line
/// each ([`log_line`]); its warnings ("No config file was loaded") and
/// debug dumps are noise to them. With `IOX2_LOG_LEVEL` set, iceoryx2's
/// own logger prints in full at that level instead (to debug the
/// transport). Processes call it first thing; the transport's functions
/// call it too, so tests and tools get it without asking. Only the first
/// call acts.
pub fn quiet_logs() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        if std::env::var_os("IOX2_LOG_LEVEL").is_some() {
            set_log_level_from_env_or(LogLevel::Error);
        } else {
            // Refused only if iceoryx2 logged before: then its logger
            // stays, at the level set here.
            static LOGGER: OneLineLogger = OneLineLogger;
            let _ = set_logger(&LOGGER);
            set_log_level(LogLevel::Error);
        }
    });
}

/// The environment variable that moves iceoryx2's root directory (its
/// node and service records; `/tmp/iceoryx2/` by default) for every
/// process of the stack, e.g. into a systemd `RuntimeDirectory` of mode
/// 0700 that no other local user can create first (deploy/*.service).
pub const IPC_ROOT_ENV: &str = "VISION_TOUCH_IPC_ROOT";

/// iceoryx2's configuration (its own files or defaults) with the root
/// directory `root` (an absolute path; `None`: iceoryx2's). Every process
/// of the stack must use the same root to see the others.
pub fn ipc_config_for(root: Option<&std::ffi::OsStr>) -> Result<Config, TransportError> {
    let mut cfg = Config::global_config().clone();
    let Some(root) = root else {
        return Ok(cfg);
    };
    let bad = |why: &str| {
        TransportError::IpcRoot(format!(
            "{IPC_ROOT_ENV} = {root:?} {why} (the stack's processes keep their shared-memory \
             records there)"
        ))
    };
    let s = root.to_str().ok_or_else(|| bad("is not UTF-8"))?;
    if !s.starts_with('/') || s.contains("/../") || s.ends_with("/..") {
        return Err(bad("must be an absolute directory without `..`"));
    }
    // iceoryx2 joins names onto the root as it is: it must end with `/`.
    let dir = if s.ends_with('/') {
        s.to_owned()
    } else {
        format!("{s}/")
    };
    let path =
        Path::new(dir.as_bytes()).map_err(|e| bad(&format!("is refused by iceoryx2 ({e:?})")))?;
    cfg.global.set_root_path(&path);
    Ok(cfg)
}

/// The configuration every node of this process uses: [`ipc_config_for`]
/// of `$VISION_TOUCH_IPC_ROOT`, read once.
pub fn stack_config() -> Result<&'static Config, TransportError> {
    static CONFIG: std::sync::OnceLock<Result<Config, String>> = std::sync::OnceLock::new();
    CONFIG
        .get_or_init(|| {
            quiet_logs();
            ipc_config_for(std::env::var_os(IPC_ROOT_ENV).as_deref()).map_err(|e| e.to_string())
        })
        .as_ref()
        .map_err(|e| TransportError::IpcRoot(e.clone()))
}

/// Creates a node named `name` under [`stack_config`]. Signal handling is
/// left to the process (iceoryx2's own handler is disabled), and stale
/// resources of dead nodes are removed first, so a previous `kill -9` never
/// breaks a start.
pub fn create_node(name: &str) -> Result<StackNode, TransportError> {
    create_node_with(name, stack_config()?)
}

fn create_node_with(name: &str, config: &Config) -> Result<StackNode, TransportError> {
    cleanup_dead_nodes();
    let node_name = NodeName::new(name).map_err(|e| ipc_err(name, "node name", e))?;
    NodeBuilder::new()
        .config(config)
        .name(&node_name)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|e| ipc_err(name, "creating node", e))
}

/// How long a real-time node ([`create_rt_node`]) waits for shared memory
/// that another process is still setting up, where iceoryx2 waits up to
/// its `global.creation_timeout` (1 s by default) in 1 ms sleeps: when a
/// peer joins a service the loop publishes or reads, the next send or
/// receive on the loop's thread opens that peer's connection.
pub const RT_CREATION_TIMEOUT: std::time::Duration = std::time::Duration::from_millis(2);

/// As [`create_node`], for a real-time loop: its waits for a peer's shared
/// memory end after [`RT_CREATION_TIMEOUT`]. A connection not ready by
/// then is given up and counted ([`degraded_connections`]); opening a
/// service at start-up is retried (see [`Channel::open`]).
pub fn create_rt_node(name: &str) -> Result<StackNode, TransportError> {
    let mut config = stack_config()?.clone();
    config.global.creation_timeout = RT_CREATION_TIMEOUT;
    create_node_with(name, &config)
}

static DEGRADED: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// Connections to a peer that this process's ports could not set up, or
/// found corrupted, so far. iceoryx2 reports them through the ports'
/// degradation handler, set here to count and go on without its warning
/// (which formats text: an allocation on a real-time thread); the
/// controller's monitor thread logs the count's growth.
pub fn degraded_connections() -> u64 {
    DEGRADED.load(std::sync::atomic::Ordering::Relaxed)
}

fn count_degradation(
    _cause: iceoryx2::port::DegradationCause,
    _info: &iceoryx2::port::DegradationInfo,
) -> iceoryx2::port::DegradationAction {
    DEGRADED.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    iceoryx2::port::DegradationAction::Ignore
}

/// Removes the shared-memory resources of nodes whose process died; returns
/// how many dead nodes were found.
pub fn cleanup_dead_nodes() -> usize {
    quiet_logs();
    let Ok(config) = stack_config() else {
        return 0;
    };
    let mut dead = Vec::new();
    let _ = StackNode::list(config, |state| {
        if let NodeState::Dead(view) = state {
            dead.push(view);
        }
        CallbackProgression::Continue
    });
    let n = dead.len();
    for view in dead {
        let _ = view.try_remove_stale_resources();
    }
    n
}

fn attribute_key() -> AttributeKey {
    AttributeKey::new(SCHEMA_ATTRIBUTE.as_bytes()).expect("valid attribute key")
}

fn version_value(version: u32) -> AttributeValue {
    AttributeValue::new(version.to_string().as_bytes()).expect("valid attribute value")
}

/// The schema version a service was created with; `None` if the service
/// does not exist, `Some("none")` without the attribute.
pub fn service_schema_version(name: &str) -> Option<String> {
    quiet_logs();
    let sn = ServiceName::new(name).ok()?;
    let details = ipc::Service::details(
        &sn,
        stack_config().ok()?,
        MessagingPattern::PublishSubscribe,
    )
    .ok()??;
    let attrs = details.static_details.attributes();
    let key = attribute_key();
    Some(
        attrs
            .key_value(&key, 0)
            .map(|v| v.to_string())
            .unwrap_or_else(|| "none".into()),
    )
}

/// Whether opening a service failed only because another process is
/// creating or removing it at the same moment.
fn in_flux(e: &PublishSubscribeOpenOrCreateError) -> bool {
    use PublishSubscribeOpenError as O;
    use PublishSubscribeOpenOrCreateError as E;
    use iceoryx2::service::builder::publish_subscribe::PublishSubscribeCreateError as C;
    matches!(
        e,
        E::SystemInFlux
            | E::PublishSubscribeOpenError(
                O::DoesNotExist
                    | O::HangsInCreation
                    | O::ServiceInCorruptedState
                    | O::IsMarkedForDestruction
            )
            | E::PublishSubscribeCreateError(
                C::AlreadyExists | C::IsBeingCreatedByAnotherInstance | C::HangsInCreation
            )
    )
}

/// A typed service of the stack, opened or created with the version
/// handshake.
pub struct Channel<T: Message> {
    name: String,
    factory: iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, T, ()>,
}

impl<T: Message> Channel<T> {
    /// Opens `T`'s topic in `namespace`, creating it if absent.
    pub fn open(node: &StackNode, namespace: &str) -> Result<Self, TransportError> {
        Self::open_as_version(node, namespace, SCHEMA_VERSION)
    }

    /// As [`Channel::open`] but claiming schema `version`: what a process
    /// built from another version does (tests use it to play one).
    #[doc(hidden)]
    pub fn open_as_version(
        node: &StackNode,
        namespace: &str,
        version: u32,
    ) -> Result<Self, TransportError> {
        let name = service_name(namespace, T::TOPIC);
        let sn = ServiceName::new(&name).map_err(|e| ipc_err(&name, "service name", e))?;
        let s = ServiceSettings::of::<T>();
        let verifier = AttributeVerifier::new()
            .require(&attribute_key(), &version_value(version))
            .map_err(|e| ipc_err(&name, "attribute", e))?;
        let open = || {
            node.service_builder(&sn)
                .publish_subscribe::<T>()
                .subscriber_max_buffer_size(s.buffer)
                .max_publishers(s.publishers)
                .max_subscribers(s.subscribers)
                .history_size(0)
                .enable_safe_overflow(true)
                .open_or_create_with_attributes(&verifier)
        };
        // A real-time node waits only briefly for a service another process
        // is creating or removing (create_rt_node), and sees it half made:
        // at start-up, try again for two seconds.
        let started = std::time::Instant::now();
        let mut opened = open();
        while opened.as_ref().err().is_some_and(in_flux)
            && started.elapsed() < std::time::Duration::from_secs(2)
        {
            std::thread::sleep(std::time::Duration::from_millis(5));
            opened = open();
        }
        match opened {
            Ok(factory) => {
                // Opening accepts a service that allows more publishers or
                // subscribers than asked for; the one-owner rule and the
                // readers' limit must not depend on who created it.
                let c = factory.static_config();
                for (what, found, expected) in [
                    ("publishers", c.max_publishers(), s.publishers),
                    ("subscribers", c.max_subscribers(), s.subscribers),
                ] {
                    if found != expected {
                        return Err(TransportError::ForeignSettings {
                            service: name,
                            what,
                            found,
                            expected,
                        });
                    }
                }
                Ok(Self { name, factory })
            }
            Err(e) => {
                let mismatch = matches!(
                    e,
                    PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
                        PublishSubscribeOpenError::IncompatibleAttributes
                            | PublishSubscribeOpenError::IncompatibleTypes
                    )
                );
                if mismatch
                    && let Some(theirs) = service_schema_version(&name)
                    && theirs != version.to_string()
                {
                    return Err(TransportError::SchemaMismatch {
                        service: name,
                        ours: version,
                        theirs,
                    });
                }
                Err(ipc_err(&name, "opening service", e))
            }
        }
    }

    /// The full service name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// A publisher on this service.
    pub fn publisher(&self) -> Result<Pub<T>, TransportError> {
        use iceoryx2::port::publisher::PublisherCreateError;
        self.factory
            .publisher_builder()
            .set_degradation_handler(count_degradation)
            .create()
            .map_err(|e| match (e, owner_of(T::TOPIC)) {
                (PublisherCreateError::ExceedsMaxSupportedPublishers, Some(owner)) => {
                    TransportError::PublisherTaken {
                        service: self.name.clone(),
                        max: ServiceSettings::of::<T>().publishers,
                        owner,
                    }
                }
                (e, _) => ipc_err(&self.name, "creating publisher", e),
            })
    }

    /// A subscriber queueing up to the topic's buffer size (oldest samples
    /// are dropped when full).
    pub fn subscriber(&self) -> Result<Sub<T>, TransportError> {
        use iceoryx2::port::subscriber::SubscriberCreateError;
        let settings = ServiceSettings::of::<T>();
        self.factory
            .subscriber_builder()
            .buffer_size(settings.buffer)
            .set_degradation_handler(count_degradation)
            .create()
            .map_err(|e| match (e, readers_of(T::TOPIC)) {
                (SubscriberCreateError::ExceedsMaxSupportedSubscribers, Some(readers)) => {
                    TransportError::SubscribersTaken {
                        service: self.name.clone(),
                        max: settings.subscribers,
                        readers,
                    }
                }
                (e, _) => ipc_err(&self.name, "creating subscriber", e),
            })
    }
}

/// Opens `T`'s service and returns a publisher on it.
pub fn publisher<T: Message>(node: &StackNode, namespace: &str) -> Result<Pub<T>, TransportError> {
    Channel::<T>::open(node, namespace)?.publisher()
}

/// Opens `T`'s service and returns a subscriber on it.
pub fn subscriber<T: Message>(node: &StackNode, namespace: &str) -> Result<Sub<T>, TransportError> {
    Channel::<T>::open(node, namespace)?.subscriber()
}

/// What failed in a publication or a receive, without iceoryx2's details:
/// the `try_` functions return it because building [`TransportError`]'s
/// text allocates, and the real-time loop must not, even when it fails.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Failure {
    /// No sample could be loaned (`LoanError`).
    Loan,
    /// The loaned sample could not be sent (`SendError`).
    Send,
    /// A receive failed (`ReceiveError`).
    Receive,
}

impl Failure {
    /// What was being done, as [`TransportError::Ipc`] words it.
    pub fn what(self) -> &'static str {
        match self {
            Failure::Loan => "loaning sample",
            Failure::Send => "sending",
            Failure::Receive => "receiving",
        }
    }
}

fn detailed<T: Message>(f: Failure, e: &dyn core::fmt::Debug) -> TransportError {
    ipc_err(T::TOPIC, f.what(), e)
}

/// Publishes a copy of `msg` (for the small messages). Never allocates
/// unless it fails.
pub fn send<T: Message>(publisher: &Pub<T>, msg: &T) -> Result<(), TransportError> {
    copy_out(publisher, msg, detailed::<T>)
}

/// As [`send`], and never allocates, even when it fails.
pub fn try_send<T: Message>(publisher: &Pub<T>, msg: &T) -> Result<(), Failure> {
    copy_out(publisher, msg, |f, _| f)
}

fn copy_out<T: Message, E>(
    publisher: &Pub<T>,
    msg: &T,
    err: impl FnOnce(Failure, &dyn core::fmt::Debug) -> E,
) -> Result<(), E> {
    let sample = match publisher.loan_uninit() {
        Ok(s) => s,
        Err(e) => return Err(err(Failure::Loan, &e)),
    };
    sample
        .write_payload(*msg)
        .send()
        .map(|_| ())
        .map_err(|e| err(Failure::Send, &e))
}

/// Builds a message in place in shared memory (zeroed first) and publishes
/// it: for large messages that must not be copied through the stack.
pub fn send_with<T: Message>(
    publisher: &Pub<T>,
    fill: impl FnOnce(&mut T),
) -> Result<(), TransportError> {
    fill_out(publisher, fill, detailed::<T>)
}

/// As [`send_with`], and never allocates, even when it fails.
pub fn try_send_with<T: Message>(
    publisher: &Pub<T>,
    fill: impl FnOnce(&mut T),
) -> Result<(), Failure> {
    fill_out(publisher, fill, |f, _| f)
}

fn fill_out<T: Message, E>(
    publisher: &Pub<T>,
    fill: impl FnOnce(&mut T),
    err: impl FnOnce(Failure, &dyn core::fmt::Debug) -> E,
) -> Result<(), E> {
    let mut sample = match publisher.loan_uninit() {
        Ok(s) => s,
        Err(e) => return Err(err(Failure::Loan, &e)),
    };
    let slot = sample.payload_mut();
    // SAFETY: messages are `Zeroable`, so all-zero bytes are a valid value;
    // they are written in place (`T::zeroed()` would build the value on the
    // stack first, and a camera frame is larger than a real-time stack).
    unsafe { core::ptr::write_bytes(slot.as_mut_ptr(), 0, 1) };
    // SAFETY: initialised just above.
    fill(unsafe { slot.assume_init_mut() });
    // SAFETY: initialised above.
    let sample = unsafe { sample.assume_init() };
    sample
        .send()
        .map(|_| ())
        .map_err(|e| err(Failure::Send, &e))
}

/// Receives every queued sample, calling `f` on each; returns how many.
pub fn drain<T: Message>(subscriber: &Sub<T>, f: impl FnMut(&T)) -> Result<usize, TransportError> {
    drain_into(subscriber, f, detailed::<T>)
}

/// As [`drain`], and never allocates, even when a receive fails.
pub fn try_drain<T: Message>(subscriber: &Sub<T>, f: impl FnMut(&T)) -> Result<usize, Failure> {
    drain_into(subscriber, f, |f, _| f)
}

/// As [`try_drain`], but takes at most `max` messages: a loop with a
/// deadline bounds its work per cycle whatever its peers publish; the rest
/// stays queued for the next call. Never allocates.
pub fn try_drain_at_most<T: Message>(
    subscriber: &Sub<T>,
    max: usize,
    f: impl FnMut(&T),
) -> Result<usize, Failure> {
    drain_bounded(subscriber, max, f, |f, _| f)
}

/// As [`drain`], at most `max` messages (see [`try_drain_at_most`]).
pub fn drain_at_most<T: Message>(
    subscriber: &Sub<T>,
    max: usize,
    f: impl FnMut(&T),
) -> Result<usize, TransportError> {
    drain_bounded(subscriber, max, f, detailed::<T>)
}

fn drain_into<T: Message, E>(
    subscriber: &Sub<T>,
    f: impl FnMut(&T),
    err: impl FnOnce(Failure, &dyn core::fmt::Debug) -> E,
) -> Result<usize, E> {
    drain_bounded(subscriber, usize::MAX, f, err)
}

fn drain_bounded<T: Message, E>(
    subscriber: &Sub<T>,
    max: usize,
    mut f: impl FnMut(&T),
    err: impl FnOnce(Failure, &dyn core::fmt::Debug) -> E,
) -> Result<usize, E> {
    let mut n = 0;
    while n < max {
        match subscriber.receive() {
            Ok(Some(s)) => {
                f(s.payload());
                n += 1;
            }
            Ok(None) => return Ok(n),
            Err(e) => return Err(err(Failure::Receive, &e)),
        }
    }
    Ok(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iceoryx2_messages_become_one_short_line() {
        // What its debug dumps look like: many lines of configuration.
        let dump = format!(
            "Unable to remove stale resources.\n{}",
            "  Config { global: Global { root_path: \"/tmp/iceoryx2/\" } }\n".repeat(100)
        );
        let line = log_line(LogLevel::Error, &dump);
        assert!(!line.contains('\n'), "{line}");
        assert_eq!(line.chars().count(), MAX_LOG_LINE, "{line}");
        assert!(line.starts_with("iceoryx2 error: Unable to remove stale resources. Config {"));
        assert!(line.ends_with('…'));
        assert_eq!(
            log_line(LogLevel::Warn, "short  one\n"),
            "iceoryx2 warning: short one"
        );
    }

    #[test]
    fn the_ipc_root_must_be_an_absolute_directory() {
        use std::ffi::OsStr;
        let root = |s: &str| {
            ipc_config_for(Some(OsStr::new(s))).map(|c| c.global.root_path().as_str().to_owned())
        };
        assert_eq!(
            root("/run/vision-touch/iceoryx2").unwrap(),
            "/run/vision-touch/iceoryx2/"
        );
        assert_eq!(root("/run/vt/").unwrap(), "/run/vt/");
        for bad in ["relative/dir", "", "/run/../tmp"] {
            let e = root(bad).unwrap_err().to_string();
            assert!(
                e.contains(IPC_ROOT_ENV) && e.contains("absolute"),
                "{bad}: {e}"
            );
        }
        let default = ipc_config_for(None).unwrap();
        assert_eq!(
            default.global.root_path(),
            Config::global_config().global.root_path()
        );
    }

    #[test]
    fn quiet_logs_lets_only_errors_through() {
        quiet_logs();
        if std::env::var_os("IOX2_LOG_LEVEL").is_none() {
            assert_eq!(iceoryx2_log::get_log_level(), LogLevel::Error as u8);
        }
    }
}
