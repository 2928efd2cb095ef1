//! The running stack, live in Foxglove (`--foxglove-ws PORT`): the log's
//! channels, the same schemas and the same message bytes as in the MCAP
//! file, served over Foxglove's WebSocket protocol (`foxglove.websocket.v1`:
//! `serverInfo`, `advertise`, `subscribe`/`unsubscribe`, binary message
//! data) while the node writes them.
//!
//! The node never waits for a viewer: [`Hub::publish`] copies a message into
//! each subscriber's bounded queue or, when that is full, drops it for that
//! subscriber (counted). One thread accepts connections; each connection has
//! its own thread, which alone touches its socket. The controller's 1 kHz
//! loop is another process and is not touched at all. A new subscriber to
//! `/config`, `/scene` or `/events` first gets the current episode's
//! messages there, so a viewer that joins mid-episode still sees the arm,
//! the box and the configuration.

use std::collections::BTreeMap;
use std::io::ErrorKind;
use std::net::{SocketAddr, TcpListener, TcpStream, ToSocketAddrs};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use tungstenite::handshake::server::{ErrorResponse, Request, Response};
use tungstenite::http::{HeaderValue, StatusCode};
use tungstenite::protocol::WebSocketConfig;
use tungstenite::{Message, WebSocket};

use super::{LogOptions, STREAMS, Stream, channel_specs};

/// The WebSocket subprotocol a client must offer.
pub const SUBPROTOCOL: &str = "foxglove.websocket.v1";
/// Connections served at once; more are refused.
pub const MAX_CLIENTS: usize = 8;
/// Messages queued per subscriber before its newest are dropped (about a
/// second of every channel).
const QUEUE: usize = 8192;
/// The largest message a client may send (its requests are small JSON).
const CLIENT_MESSAGE_LIMIT: usize = 64 << 10;
/// How long a client may take over its handshake, and a write may block.
const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(5);
const WRITE_TIMEOUT: Duration = Duration::from_secs(5);
/// How often a connection's thread looks for queued messages while its
/// client is silent.
const POLL: Duration = Duration::from_millis(5);
/// The opcode of a binary message-data frame.
const MESSAGE_DATA: u8 = 1;

/// The channels that keep their current episode's messages for new
/// subscribers, and how many: the configuration, the scene (the arm and
/// peg, then the box) and the events (the reset, the stages reached).
const LATCHED: [(Stream, usize); 3] =
    [(Stream::Config, 1), (Stream::Scene, 2), (Stream::Events, 8)];

/// The WebSocket id of a stream's channel (never 0).
fn channel_id(s: Stream) -> u32 {
    s as u32 + 1
}

/// A channel as `advertise` lists it.
#[derive(Debug, serde::Serialize)]
#[serde(rename_all = "camelCase")]
struct Advertised {
    id: u32,
    topic: &'static str,
    encoding: &'static str,
    schema_name: String,
    schema: String,
    schema_encoding: &'static str,
}

/// A message on its way to one subscriber.
#[derive(Debug)]
struct Outgoing {
    channel: u32,
    log_ns: u64,
    data: Arc<[u8]>,
}

/// A retained message: its log time and bytes.
type Kept = (u64, Arc<[u8]>);

/// One connection as the publisher sees it.
#[derive(Debug)]
struct Client {
    id: u64,
    tx: SyncSender<Outgoing>,
    /// Subscribed, by channel id.
    wanted: Arc<[AtomicBool]>,
    /// Messages dropped for it (its queue full).
    dropped: Arc<AtomicU64>,
}

/// What the node's log writers publish into and the connections read from.
#[derive(Debug)]
pub struct Hub {
    channels: Vec<Advertised>,
    clients: Mutex<Vec<Client>>,
    /// `clients.len()`, read without the lock on every message.
    subscribers: AtomicUsize,
    /// Connections open (handshaking ones included).
    sessions: AtomicUsize,
    next_client: AtomicU64,
    /// The latched channels' retained messages, by channel id.
    latched: Mutex<BTreeMap<u32, Vec<Kept>>>,
    dropped: AtomicU64,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // A connection thread that panicked holding it left consistent data.
    m.lock().unwrap_or_else(|p| p.into_inner())
}

impl Hub {
    fn new(opts: &LogOptions) -> Self {
        let channels = channel_specs(opts)
            .into_iter()
            .map(|c| Advertised {
                id: channel_id(c.stream),
                topic: c.topic,
                encoding: c.message_encoding,
                schema_name: c.schema_name,
                schema: c.schema,
                schema_encoding: c.schema_encoding,
            })
            .collect();
        Self {
            channels,
            clients: Mutex::new(Vec::new()),
            subscribers: AtomicUsize::new(0),
            sessions: AtomicUsize::new(0),
            next_client: AtomicU64::new(1),
            latched: Mutex::new(BTreeMap::new()),
            dropped: AtomicU64::new(0),
        }
    }

    /// Hands one logged message to every client subscribed to its channel;
    /// never blocks on a client.
    pub(super) fn publish(&self, stream: Stream, log_ns: u64, data: &[u8]) {
        let channel = channel_id(stream);
        let keep = LATCHED.iter().find(|(s, _)| *s == stream);
        if self.subscribers.load(Ordering::Acquire) == 0 && keep.is_none() {
            return;
        }
        let data: Arc<[u8]> = data.into();
        // A latched channel's message is kept and handed out under one
        // lock, which a new subscriber takes to subscribe and copy what is
        // kept: it gets each message once, kept or queued.
        let _latched = keep.map(|&(s, n)| {
            let mut latched = lock(&self.latched);
            // A new episode's configuration starts its messages afresh.
            if s == Stream::Config {
                latched.clear();
            }
            let kept = latched.entry(channel).or_default();
            if kept.len() == n {
                kept.remove(0);
            }
            kept.push((log_ns, data.clone()));
            latched
        });
        for c in lock(&self.clients).iter() {
            if !c.wanted[channel as usize].load(Ordering::Acquire) {
                continue;
            }
            let m = Outgoing {
                channel,
                log_ns,
                data: data.clone(),
            };
            if let Err(TrySendError::Full(_)) = c.tx.try_send(m) {
                self.dropped.fetch_add(1, Ordering::Relaxed);
                c.dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// Unsubscribes a connection from `channel`, under the same lock as
    /// [`Hub::subscribe`], so that a message cannot be both kept for a
    /// later subscription and queued from this one.
    fn unsubscribe(&self, wanted: &[AtomicBool], channel: u32) {
        let _latched = lock(&self.latched);
        wanted[channel as usize].store(false, Ordering::Release);
    }

    /// Subscribes a connection to `channel` and returns the messages kept
    /// for it (none for an unlatched channel), as one step against
    /// [`Hub::publish`].
    fn subscribe(&self, wanted: &[AtomicBool], channel: u32) -> Vec<Kept> {
        let latched = lock(&self.latched);
        wanted[channel as usize].store(true, Ordering::Release);
        latched.get(&channel).cloned().unwrap_or_default()
    }

    /// Messages dropped for subscribers that fell behind, so far.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }

    fn register(&self) -> Registered {
        let (tx, rx) = std::sync::mpsc::sync_channel(QUEUE);
        let wanted: Arc<[AtomicBool]> = (0..=STREAMS).map(|_| AtomicBool::new(false)).collect();
        let dropped = Arc::new(AtomicU64::new(0));
        let id = self.next_client.fetch_add(1, Ordering::Relaxed);
        let mut clients = lock(&self.clients);
        clients.push(Client {
            id,
            tx,
            wanted: wanted.clone(),
            dropped: dropped.clone(),
        });
        self.subscribers.store(clients.len(), Ordering::Release);
        Registered {
            id,
            rx,
            wanted,
            dropped,
        }
    }

    fn unregister(&self, id: u64) {
        let mut clients = lock(&self.clients);
        clients.retain(|c| c.id != id);
        self.subscribers.store(clients.len(), Ordering::Release);
    }
}

/// A connection's side of its registration.
struct Registered {
    id: u64,
    rx: Receiver<Outgoing>,
    wanted: Arc<[AtomicBool]>,
    dropped: Arc<AtomicU64>,
}

/// The server: listening, with its hub.
pub struct LiveServer {
    hub: Arc<Hub>,
    addr: SocketAddr,
}

impl LiveServer {
    /// Listens on `addr` (port 0: any free one) and serves the channels a
    /// log with `opts` has, from a thread of its own.
    pub fn start(addr: impl ToSocketAddrs, opts: &LogOptions) -> std::io::Result<Self> {
        let listener = TcpListener::bind(addr)?;
        let addr = listener.local_addr()?;
        let hub = Arc::new(Hub::new(opts));
        let h = hub.clone();
        std::thread::Builder::new()
            .name("foxglove-ws".into())
            .spawn(move || accept_loop(listener, h))?;
        Ok(Self { hub, addr })
    }

    /// The address it listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// What log writers publish into ([`super::LogWriter::serve_live`]).
    pub fn hub(&self) -> Arc<Hub> {
        self.hub.clone()
    }
}

fn accept_loop(listener: TcpListener, hub: Arc<Hub>) {
    for stream in listener.incoming() {
        let Ok(stream) = stream else { continue };
        let peer = stream
            .peer_addr()
            .map_or_else(|_| "?".into(), |a| a.to_string());
        if hub.sessions.fetch_add(1, Ordering::AcqRel) >= MAX_CLIENTS {
            hub.sessions.fetch_sub(1, Ordering::AcqRel);
            eprintln!("node: Foxglove WebSocket: {peer} refused, {MAX_CLIENTS} already connected");
            refuse_busy(stream);
            continue;
        }
        let h = hub.clone();
        let spawned = std::thread::Builder::new()
            .name("foxglove-ws-client".into())
            .spawn(move || {
                if let Err(e) = serve(stream, &h) {
                    eprintln!("node: Foxglove WebSocket: {peer}: {e}");
                }
                h.sessions.fetch_sub(1, Ordering::AcqRel);
            });
        if spawned.is_err() {
            hub.sessions.fetch_sub(1, Ordering::AcqRel);
        }
    }
}

/// Answers a connection past [`MAX_CLIENTS`] with HTTP 503 and why (at
/// most a short blocking write; the accept thread goes on).
fn refuse_busy(mut stream: TcpStream) {
    use std::io::Write;
    let body = format!("{MAX_CLIENTS} viewers are already connected; try again later\n");
    let _ = stream.set_write_timeout(Some(Duration::from_millis(200)));
    let _ = write!(
        stream,
        "HTTP/1.1 503 Service Unavailable\r\nContent-Type: text/plain\r\nContent-Length: {}\r\n\
         Connection: close\r\n\r\n{body}",
        body.len()
    );
    // Closed with its request unread, the socket would be reset and the
    // answer lost: read what came (briefly) first.
    let _ = stream.shutdown(std::net::Shutdown::Write);
    let _ = stream.set_read_timeout(Some(Duration::from_millis(100)));
    let mut buf = [0u8; 4096];
    while let Ok(n) = std::io::Read::read(&mut stream, &mut buf) {
        if n == 0 {
            break;
        }
    }
}

/// Accepts the handshake when the client offers [`SUBPROTOCOL`].
#[allow(clippy::result_large_err)] // tungstenite's callback signature
fn choose_subprotocol(req: &Request, mut resp: Response) -> Result<Response, ErrorResponse> {
    let offered = req
        .headers()
        .get_all("sec-websocket-protocol")
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .any(|p| p.trim() == SUBPROTOCOL);
    if offered {
        resp.headers_mut().insert(
            "sec-websocket-protocol",
            HeaderValue::from_static(SUBPROTOCOL),
        );
        return Ok(resp);
    }
    let mut e = ErrorResponse::new(Some(format!(
        "this server speaks the {SUBPROTOCOL} subprotocol only; offer it"
    )));
    *e.status_mut() = StatusCode::BAD_REQUEST;
    Err(e)
}

/// Why a connection ended early.
#[derive(Debug, thiserror::Error)]
enum ServeError {
    #[error("{0}")]
    Io(#[from] std::io::Error),
    #[error("{0}")]
    Ws(#[from] tungstenite::Error),
    #[error("handshake: {0}")]
    Handshake(String),
}

/// One connection: the handshake, the channel list, then requests in and
/// messages out until the client leaves.
fn serve(stream: TcpStream, hub: &Hub) -> Result<(), ServeError> {
    stream.set_read_timeout(Some(HANDSHAKE_TIMEOUT))?;
    stream.set_write_timeout(Some(WRITE_TIMEOUT))?;
    stream.set_nodelay(true)?;
    let config = WebSocketConfig::default()
        .max_message_size(Some(CLIENT_MESSAGE_LIMIT))
        .max_frame_size(Some(CLIENT_MESSAGE_LIMIT));
    let mut ws = tungstenite::accept_hdr_with_config(stream, choose_subprotocol, Some(config))
        .map_err(|e| match e {
            tungstenite::HandshakeError::Failure(tungstenite::Error::Http(r)) => {
                ServeError::Handshake(format!(
                    "refused ({}): {}",
                    r.status(),
                    String::from_utf8_lossy(r.body().as_deref().unwrap_or_default())
                ))
            }
            e => ServeError::Handshake(e.to_string()),
        })?;
    ws.get_mut().set_read_timeout(Some(POLL))?;
    let info = serde_json::json!({
        "op": "serverInfo",
        "name": "vision-touch policy node",
        "capabilities": [],
        "metadata": {},
        "sessionId": format!("{}", shared_mem_schema::process::mono_now_ns()),
    });
    ws.send(Message::text(info.to_string()))?;
    let advertise = serde_json::json!({ "op": "advertise", "channels": hub.channels });
    ws.send(Message::text(advertise.to_string()))?;
    let reg = hub.register();
    let r = session(&mut ws, hub, &reg.rx, &reg.wanted);
    hub.unregister(reg.id);
    let dropped = reg.dropped.load(Ordering::Relaxed);
    if dropped > 0 {
        let peer = ws
            .get_ref()
            .peer_addr()
            .map_or_else(|_| "?".into(), |a| a.to_string());
        eprintln!(
            "node: Foxglove WebSocket: {peer}: {dropped} messages were dropped for this viewer, \
             which fell behind"
        );
    }
    r
}

/// The subscriptions of one connection: subscription id by channel id.
type Subscriptions = BTreeMap<u32, u32>;

fn session(
    ws: &mut WebSocket<TcpStream>,
    hub: &Hub,
    rx: &Receiver<Outgoing>,
    wanted: &[AtomicBool],
) -> Result<(), ServeError> {
    let mut subs = Subscriptions::new();
    loop {
        match ws.read() {
            Ok(Message::Text(t)) => {
                let (statuses, fresh) = request(&t, hub, &mut subs, wanted);
                for s in statuses {
                    ws.write(Message::text(s))?;
                }
                // Subscribed now, the latched channels' kept messages first.
                for ch in fresh {
                    for (t, data) in hub.subscribe(wanted, ch) {
                        ws.write(data_frame(subs[&ch], t, &data))?;
                    }
                }
                ws.flush()?;
            }
            Ok(Message::Binary(_)) => {
                ws.send(status(2, "this server does not accept client publishing"))?;
            }
            Ok(Message::Close(_)) => {
                // tungstenite answers the close; flush it out.
                let _ = ws.flush();
                return Ok(());
            }
            // A ping's pong is queued by tungstenite; send it now.
            Ok(_) => ws.flush()?,
            Err(tungstenite::Error::Io(e))
                if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
            Err(tungstenite::Error::ConnectionClosed | tungstenite::Error::AlreadyClosed) => {
                return Ok(());
            }
            Err(e) => {
                // Too large a request: say so (1009) before hanging up.
                if let tungstenite::Error::Capacity(c) = &e {
                    let frame = tungstenite::protocol::CloseFrame {
                        code: tungstenite::protocol::frame::coding::CloseCode::Size,
                        reason: c.to_string().into(),
                    };
                    let _ = ws.close(Some(frame)).and_then(|()| ws.flush());
                    drain(ws.get_mut());
                }
                return Err(e.into());
            }
        }
        let mut wrote = false;
        while let Ok(m) = rx.try_recv() {
            // Unsubscribed since it was queued: not sent.
            if let Some(&sub) = subs.get(&m.channel) {
                ws.write(data_frame(sub, m.log_ns, &m.data))?;
                wrote = true;
            }
        }
        if wrote {
            ws.flush()?;
        }
    }
}

/// Reads and discards what a client still sends after being closed on (at
/// most 2 s, 4 MiB), so that its socket is not reset with the close frame
/// unread.
fn drain(stream: &mut TcpStream) {
    use std::io::Read;
    let deadline = std::time::Instant::now() + Duration::from_secs(2);
    let mut buf = [0u8; 16 << 10];
    let mut total = 0;
    while std::time::Instant::now() < deadline && total < 4 << 20 {
        match stream.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => total += n,
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
            Err(_) => break,
        }
    }
}

/// A binary message-data frame: opcode, subscription id, log time (ns),
/// the message as logged.
fn data_frame(sub: u32, log_ns: u64, data: &[u8]) -> Message {
    let mut b = Vec::with_capacity(13 + data.len());
    b.push(MESSAGE_DATA);
    b.extend_from_slice(&sub.to_le_bytes());
    b.extend_from_slice(&log_ns.to_le_bytes());
    b.extend_from_slice(data);
    Message::Binary(b.into())
}

/// A `status` message (level 0 info, 1 warning, 2 error).
fn status(level: u8, message: &str) -> Message {
    Message::text(status_text(level, message))
}

fn status_text(level: u8, message: &str) -> String {
    serde_json::json!({ "op": "status", "level": level, "message": message }).to_string()
}

/// Handles one client request: the status messages to answer with, and the
/// channels newly subscribed (for [`Hub::subscribe`] to turn on).
fn request(
    text: &str,
    hub: &Hub,
    subs: &mut Subscriptions,
    wanted: &[AtomicBool],
) -> (Vec<String>, Vec<u32>) {
    let mut statuses = Vec::new();
    let mut fresh = Vec::new();
    let v: serde_json::Value = match serde_json::from_str(text) {
        Ok(v) => v,
        Err(e) => {
            statuses.push(status_text(2, &format!("not JSON: {e}")));
            return (statuses, fresh);
        }
    };
    match v["op"].as_str() {
        Some("subscribe") => {
            let Some(list) = v["subscriptions"].as_array() else {
                statuses.push(status_text(2, "subscribe: no \"subscriptions\" array"));
                return (statuses, fresh);
            };
            for s in list {
                let (Some(sub), Some(ch)) = (as_u32(&s["id"]), as_u32(&s["channelId"])) else {
                    statuses.push(status_text(
                        2,
                        &format!("subscribe: {s} needs \"id\" and \"channelId\" (u32)"),
                    ));
                    continue;
                };
                if !hub.channels.iter().any(|c| c.id == ch) {
                    statuses.push(status_text(2, &format!("subscribe: no channel {ch}")));
                } else if subs.values().any(|&x| x == sub) {
                    statuses.push(status_text(
                        2,
                        &format!("subscribe: subscription id {sub} is in use"),
                    ));
                } else if let std::collections::btree_map::Entry::Vacant(e) = subs.entry(ch) {
                    e.insert(sub);
                    fresh.push(ch);
                } else {
                    statuses.push(status_text(
                        2,
                        &format!("subscribe: channel {ch} is already subscribed"),
                    ));
                }
            }
        }
        Some("unsubscribe") => {
            let Some(ids) = v["subscriptionIds"].as_array() else {
                statuses.push(status_text(2, "unsubscribe: no \"subscriptionIds\" array"));
                return (statuses, fresh);
            };
            for id in ids {
                let found = as_u32(id).and_then(|id| {
                    subs.iter()
                        .find_map(|(&ch, &sub)| (sub == id).then_some(ch))
                });
                match found {
                    Some(ch) => {
                        subs.remove(&ch);
                        hub.unsubscribe(wanted, ch);
                    }
                    None => statuses.push(status_text(
                        1,
                        &format!("unsubscribe: no subscription {id}"),
                    )),
                }
            }
        }
        Some(op) => statuses.push(status_text(
            1,
            &format!("{op:?}: not supported by this server (it only serves channels)"),
        )),
        None => statuses.push(status_text(2, "a request without \"op\"")),
    }
    (statuses, fresh)
}

fn as_u32(v: &serde_json::Value) -> Option<u32> {
    v.as_u64().and_then(|x| u32::try_from(x).ok())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A subscriber that never reads costs the publisher nothing but the
    /// dropped copies: publishing past its queue returns at once, counted.
    #[test]
    fn a_stalled_subscriber_never_blocks_the_publisher() {
        let hub = Hub::new(&LogOptions::default());
        let Registered {
            id,
            rx,
            wanted,
            dropped,
        } = hub.register();
        assert!(
            hub.subscribe(&wanted, channel_id(Stream::Sensor))
                .is_empty()
        );
        let extra = 25;
        for i in 0..(QUEUE + extra) as u64 {
            hub.publish(Stream::Sensor, i, &[1, 2, 3]);
            // Not subscribed: never queued.
            hub.publish(Stream::Action, i, &[4]);
        }
        assert_eq!(hub.dropped(), extra as u64);
        assert_eq!(dropped.load(Ordering::Relaxed), extra as u64);
        let got: Vec<_> = rx.try_iter().collect();
        assert_eq!(got.len(), QUEUE);
        assert!(got.iter().all(|m| m.channel == channel_id(Stream::Sensor)));
        assert_eq!(got[0].log_ns, 0);
        hub.unregister(id);
        assert_eq!(hub.subscribers.load(Ordering::Acquire), 0);
        // Without subscribers, nothing is queued or dropped.
        hub.publish(Stream::Sensor, 0, &[1]);
        assert_eq!(hub.dropped(), extra as u64);
    }

    /// The current episode's configuration, scene and events are kept for
    /// late subscribers; a new configuration starts afresh.
    #[test]
    fn the_latched_channels_keep_the_current_episode() {
        let hub = Hub::new(&LogOptions::default());
        hub.publish(Stream::Config, 1, b"c1");
        hub.publish(Stream::Scene, 2, b"arm");
        hub.publish(Stream::Scene, 3, b"box");
        hub.publish(Stream::Events, 3, b"reset");
        hub.publish(Stream::Sensor, 4, b"not kept");
        let kept = |s: Stream| -> Vec<Vec<u8>> {
            lock(&hub.latched)
                .get(&channel_id(s))
                .map(|v| v.iter().map(|(_, d)| d.to_vec()).collect())
                .unwrap_or_default()
        };
        assert_eq!(kept(Stream::Scene), [b"arm".to_vec(), b"box".to_vec()]);
        assert_eq!(kept(Stream::Events), [b"reset".to_vec()]);
        assert!(kept(Stream::Sensor).is_empty());
        hub.publish(Stream::Config, 5, b"c2");
        assert_eq!(kept(Stream::Config), [b"c2".to_vec()]);
        assert!(kept(Stream::Scene).is_empty() && kept(Stream::Events).is_empty());
    }

    /// Through the real writer: an episode's configuration, then its arm
    /// and peg, are what a viewer subscribing to `/config` and `/scene`
    /// gets first; subscribing hands out the kept messages and queues the
    /// later ones, each once.
    #[test]
    fn a_late_viewer_gets_the_episodes_config_and_arm() {
        let dir = test_support::scratch_dir("ws-latched");
        let opts = LogOptions::default();
        let hub = Arc::new(Hub::new(&opts));
        let mut log = super::super::LogWriter::create_with(&dir.join("a.mcap"), opts).unwrap();
        log.serve_live(hub.clone());
        let mut world = hw_sim::WorldConfig::default();
        world.task.enabled = true;
        let config = super::super::RunConfig::new(
            super::super::RunMode::Live,
            world,
            crate::mix::EpisodePolicy::Heuristic,
            1,
            5,
        );
        log.config(1_000, &config).unwrap();
        let reg = hub.register();
        let kept_config = hub.subscribe(&reg.wanted, channel_id(Stream::Config));
        let kept_scene = hub.subscribe(&reg.wanted, channel_id(Stream::Scene));
        assert_eq!(kept_config.len(), 1);
        assert_eq!(kept_scene.len(), 1, "the arm and peg");
        let scene = String::from_utf8_lossy(&kept_scene[0].1).into_owned();
        assert!(
            scene.contains("\"arm/") && scene.contains("peg_tip"),
            "{scene}"
        );
        // Nothing kept was queued as well; the next episode's config is.
        assert_eq!(reg.rx.try_iter().count(), 0);
        log.config(2_000, &config).unwrap();
        let queued: Vec<u32> = reg.rx.try_iter().map(|m| m.channel).collect();
        assert_eq!(
            queued,
            [channel_id(Stream::Config), channel_id(Stream::Scene)]
        );
    }

    /// Requests: subscribe and unsubscribe by the protocol's fields; bad
    /// ones answered with a status naming the problem.
    #[test]
    fn requests_are_checked_and_answered() {
        let hub = Hub::new(&LogOptions::default());
        let wanted: Vec<AtomicBool> = (0..=STREAMS).map(|_| AtomicBool::new(false)).collect();
        let mut subs = Subscriptions::new();
        let ch = channel_id(Stream::Wrench);
        let (st, fresh) = request(
            &format!(r#"{{"op":"subscribe","subscriptions":[{{"id":7,"channelId":{ch}}}]}}"#),
            &hub,
            &mut subs,
            &wanted,
        );
        assert!(st.is_empty(), "{st:?}");
        assert_eq!(fresh, [ch]);
        hub.subscribe(&wanted, ch);
        assert!(wanted[ch as usize].load(Ordering::Acquire));
        for (req, says) in [
            (
                r#"{"op":"subscribe","subscriptions":[{"id":8,"channelId":0}]}"#,
                "no channel 0",
            ),
            (
                r#"{"op":"subscribe","subscriptions":[{"id":-1,"channelId":1}]}"#,
                "needs",
            ),
            (r#"{"op":"subscribe"}"#, "no \\\"subscriptions\\\""),
            (
                r#"{"op":"unsubscribe","subscriptionIds":[99]}"#,
                "no subscription 99",
            ),
            (r#"[1,2]"#, "without \\\"op\\\""),
            ("\u{0}", "not JSON"),
        ] {
            let (st, _) = request(req, &hub, &mut subs, &wanted);
            assert!(st.len() == 1 && st[0].contains(says), "{req}: {st:?}");
        }
        let (st, _) = request(
            r#"{"op":"unsubscribe","subscriptionIds":[7]}"#,
            &hub,
            &mut subs,
            &wanted,
        );
        assert!(st.is_empty() && subs.is_empty());
        assert!(!wanted[ch as usize].load(Ordering::Acquire));
    }
}
