//! An external 6-axis force/torque sensor, a wrench source a backend can be
//! given (the Franka backend's `wrench = "net_ft"`): an ATI Net F/T (the paper's real robot carried an ATI Gamma)
//! over its RDT ("raw data transfer") UDP protocol.
//!
//! The protocol, from ATI's Net F/T manual: the client sends an 8-byte
//! request to UDP port 49152 (big-endian `u16` header 0x1234, `u16`
//! command, `u32` sample count; command 2 with count 0 streams until
//! command 0 stops it); the sensor answers with 36-byte records (big-endian
//! `u32` RDT sequence, `u32` F/T sequence, `u32` status, then six `i32`
//! counts Fx, Fy, Fz, Tx, Ty, Tz), at the rate set on its web page (up to
//! 7 kHz). Counts become newtons and newton-metres through the
//! calibration's counts per force and per torque (the sensor's web page and
//! its `netftapi2.xml` give them).
//!
//! In the loop, [`NetFt::read`] takes the records that have arrived (at
//! most [`MAX_RECORDS_PER_READ`]) from a non-blocking socket into a stack
//! buffer, keeps the newest, and never waits or allocates. A record whose
//! RDT sequence is not newer than the last one taken (a replay, a
//! reordered datagram) is dropped and counted: it neither changes the
//! wrench nor counts as the sensor speaking. A sensor silent for longer
//! than `timeout_ms`, or a record whose status word is not zero (a
//! saturated gauge, a broken gauge, an internal error), is the daemon's
//! Fault [`FAULT_FT_SENSOR`] with the reason. The values are in the
//! sensor's frame, as the robot descriptions' wrist sensor reads them,
//! less the mean of the records of the first `tare_ms` at start-up (the
//! sensor's bias and the tool's weight at rest; docs/franka.md).

use crate::backend::HardwareError;
use crate::config::NetFtConfig;
use crate::shared::FAULT_FT_SENSOR;
use std::net::UdpSocket;
use std::time::{Duration, Instant};

/// The RDT port of a Net F/T.
pub const RDT_PORT: u16 = 49152;
/// The header word of an RDT request.
const HEADER: u16 = 0x1234;
/// RDT command: stop streaming.
pub const CMD_STOP: u16 = 0x0000;
/// RDT command: start real-time streaming.
pub const CMD_START: u16 = 0x0002;
/// Bytes of one RDT record.
pub const RECORD_BYTES: usize = 36;

/// An RDT request: `command`, then `count` records (0: until stopped).
pub fn request(command: u16, count: u32) -> [u8; 8] {
    let mut r = [0u8; 8];
    r[0..2].copy_from_slice(&HEADER.to_be_bytes());
    r[2..4].copy_from_slice(&command.to_be_bytes());
    r[4..8].copy_from_slice(&count.to_be_bytes());
    r
}

/// One RDT record.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Record {
    /// The packet's sequence number.
    pub rdt_sequence: u32,
    /// The sensor's internal sample number.
    pub ft_sequence: u32,
    /// The status word: 0 when healthy.
    pub status: u32,
    /// Fx, Fy, Fz, Tx, Ty, Tz in counts.
    pub counts: [i32; 6],
}

impl Record {
    /// Reads a record; `None` if `b` is not one record long.
    pub fn parse(b: &[u8]) -> Option<Self> {
        if b.len() != RECORD_BYTES {
            return None;
        }
        let word = |i: usize| [b[4 * i], b[4 * i + 1], b[4 * i + 2], b[4 * i + 3]];
        let mut counts = [0i32; 6];
        for (j, c) in counts.iter_mut().enumerate() {
            *c = i32::from_be_bytes(word(3 + j));
        }
        Some(Self {
            rdt_sequence: u32::from_be_bytes(word(0)),
            ft_sequence: u32::from_be_bytes(word(1)),
            status: u32::from_be_bytes(word(2)),
            counts,
        })
    }

    /// The record's 36 bytes (what a sensor sends).
    pub fn to_bytes(&self) -> [u8; RECORD_BYTES] {
        let mut b = [0u8; RECORD_BYTES];
        b[0..4].copy_from_slice(&self.rdt_sequence.to_be_bytes());
        b[4..8].copy_from_slice(&self.ft_sequence.to_be_bytes());
        b[8..12].copy_from_slice(&self.status.to_be_bytes());
        for (j, c) in self.counts.iter().enumerate() {
            b[12 + 4 * j..16 + 4 * j].copy_from_slice(&c.to_be_bytes());
        }
        b
    }
}

/// Most datagrams one [`NetFt::read`] takes.
pub const MAX_RECORDS_PER_READ: usize = 16;

/// A streaming Net F/T.
#[derive(Debug)]
pub struct NetFt {
    socket: UdpSocket,
    cfg: NetFtConfig,
    wrench: [f64; 6],
    /// What the readings are taken relative to (the tare), N and N·m.
    bias: [f64; 6],
    /// When the newest record arrived (the loop's clock, ns).
    last_ns: u64,
    /// The RDT sequence of the newest record taken (`None` before the first).
    last_sequence: Option<u32>,
    /// Records taken, datagrams that were not one record, and records
    /// dropped for a sequence not newer than the last.
    records: u64,
    malformed: u64,
    stale: u64,
}

/// Whether RDT sequence `next` comes after `last` (the counter wraps: a
/// step forward of less than half its range is newer).
pub fn is_newer(next: u32, last: u32) -> bool {
    let d = next.wrapping_sub(last);
    d != 0 && d < 1 << 31
}

fn sensor_error(reason: String) -> HardwareError {
    HardwareError::Robot {
        code: FAULT_FT_SENSOR,
        reason,
    }
}

impl NetFt {
    /// Starts the stream of the sensor at `cfg.address` and waits up to
    /// `cfg.start_timeout_s` for its first healthy record (a sensor that
    /// does not answer is an error naming the address). Not real-time:
    /// called before the loop starts; `now_ns` is the loop's clock then.
    pub fn connect(cfg: &NetFtConfig, now_ns: u64) -> Result<Self, HardwareError> {
        let at = format!("`backend.franka.net_ft.address` = {:?}", cfg.address);
        let io = |what: &str, e: std::io::Error| sensor_error(format!("{what} {at}: {e}"));
        let target = if cfg.address.contains(':') {
            cfg.address.clone()
        } else {
            format!("{}:{RDT_PORT}", cfg.address)
        };
        let socket = UdpSocket::bind("0.0.0.0:0").map_err(|e| io("binding a socket for", e))?;
        socket
            .connect(&target)
            .map_err(|e| io("addressing the F/T sensor at", e))?;
        let mut s = Self {
            socket,
            cfg: cfg.clone(),
            wrench: [0.0; 6],
            bias: [0.0; 6],
            last_ns: now_ns,
            last_sequence: None,
            records: 0,
            malformed: 0,
            stale: 0,
        };
        // The start request again every 100 ms until a record comes: UDP
        // may lose the first one.
        let start = Instant::now();
        let deadline = Duration::from_secs_f64(cfg.start_timeout_s);
        s.socket
            .set_read_timeout(Some(Duration::from_millis(100)))
            .map_err(|e| io("configuring the socket of", e))?;
        let mut buf = [0u8; 64];
        loop {
            // A refused send (nothing listening yet on a local address)
            // is retried like a lost request.
            let sent = Instant::now();
            let _ = s.socket.send(&request(CMD_START, 0));
            match s.socket.recv(&mut buf) {
                Ok(n) => {
                    if let Some(r) = Record::parse(&buf[..n]) {
                        // The first record: never stale.
                        s.take(&r, now_ns)?;
                        break;
                    }
                    s.malformed += 1;
                }
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) => {}
                Err(e) if e.kind() == std::io::ErrorKind::ConnectionRefused => {
                    // The refusal (ICMP) comes back at once: wait out the
                    // 100 ms rather than flood the address.
                    std::thread::sleep(Duration::from_millis(100).saturating_sub(sent.elapsed()));
                }
                Err(e) => return Err(io("reading the F/T sensor at", e)),
            }
            if start.elapsed() > deadline {
                return Err(sensor_error(format!(
                    "the F/T sensor at {at} sent no record in {} s (is it on, streaming RDT \
                     on UDP {RDT_PORT}, and is the address right?)",
                    cfg.start_timeout_s
                )));
            }
        }
        s.tare(now_ns).map_err(|e| match e {
            HardwareError::Robot { code, reason } => HardwareError::Robot {
                code,
                reason: format!("while taring: {reason}"),
            },
            e => e,
        })?;
        s.socket
            .set_nonblocking(true)
            .map_err(|e| io("configuring the socket of", e))?;
        Ok(s)
    }

    /// Averages the records of the next `tare_ms` (with the first one
    /// already taken) into the bias later readings are taken relative to.
    /// Before the loop, with the arm at rest: it blocks for `tare_ms`.
    fn tare(&mut self, now_ns: u64) -> Result<(), HardwareError> {
        if self.cfg.tare_ms <= 0.0 {
            return Ok(());
        }
        let mut sum = self.wrench;
        let mut n = 1u32;
        let start = Instant::now();
        let window = Duration::from_secs_f64(self.cfg.tare_ms * 1e-3);
        let mut buf = [0u8; 64];
        while start.elapsed() < window {
            let left = window
                .saturating_sub(start.elapsed())
                .max(Duration::from_millis(1));
            self.socket
                .set_read_timeout(Some(left))
                .map_err(|e| sensor_error(format!("configuring the socket: {e}")))?;
            match self.socket.recv(&mut buf) {
                Ok(k) => match Record::parse(&buf[..k]) {
                    Some(r) => {
                        if self.take(&r, now_ns)? {
                            n += 1;
                            for (a, w) in sum.iter_mut().zip(self.wrench) {
                                *a += w;
                            }
                        }
                    }
                    None => self.malformed += 1,
                },
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) => {}
                Err(e) => return Err(sensor_error(format!("reading the F/T sensor: {e}"))),
            }
        }
        for (b, a) in self.bias.iter_mut().zip(sum) {
            *b = a / f64::from(n);
        }
        for (w, b) in self.wrench.iter_mut().zip(self.bias) {
            *w -= b;
        }
        Ok(())
    }

    /// Takes `r` unless its sequence is not newer than the last taken
    /// (then counted as stale and `Ok(false)`); a faulted status is an error.
    fn take(&mut self, r: &Record, now_ns: u64) -> Result<bool, HardwareError> {
        if self
            .last_sequence
            .is_some_and(|last| !is_newer(r.rdt_sequence, last))
        {
            self.stale += 1;
            return Ok(false);
        }
        if r.status != 0 {
            return Err(sensor_error(format!(
                "the F/T sensor reports status {:#010x} (record {}): a gauge saturated or \
                 failed, see the sensor's manual",
                r.status, r.rdt_sequence
            )));
        }
        for (j, (w, &c)) in self.wrench.iter_mut().zip(&r.counts).enumerate() {
            let per = if j < 3 {
                self.cfg.counts_per_force
            } else {
                self.cfg.counts_per_torque
            };
            *w = f64::from(c) / per - self.bias[j];
        }
        self.last_ns = now_ns;
        self.last_sequence = Some(r.rdt_sequence);
        self.records += 1;
        Ok(true)
    }

    /// The newest wrench (N, N·m, the sensor's frame, less the tare) after taking the
    /// records that have arrived (at most [`MAX_RECORDS_PER_READ`]); an error if the newest is older than
    /// `timeout_ms` at `now_ns` or reports a fault. Never blocks or
    /// allocates.
    pub fn read(&mut self, now_ns: u64) -> Result<[f64; 6], HardwareError> {
        let mut buf = [0u8; 64];
        // Bounded: the sensor streams at most ~7 records per millisecond;
        // a flood of datagrams waits in the socket for the next cycle.
        for _ in 0..MAX_RECORDS_PER_READ {
            match self.socket.recv(&mut buf) {
                Ok(n) => match Record::parse(&buf[..n]) {
                    Some(r) => {
                        self.take(&r, now_ns)?;
                    }
                    None => self.malformed += 1,
                },
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => break,
                // A refusal (an ICMP error from a sensor that went away)
                // shows as silence below.
                Err(e) if e.kind() == std::io::ErrorKind::ConnectionRefused => break,
                Err(e) => {
                    return Err(sensor_error(format!("reading the F/T sensor: {e}")));
                }
            }
        }
        let age_ms = now_ns.saturating_sub(self.last_ns) as f64 * 1e-6;
        if age_ms > self.cfg.timeout_ms {
            // A sensor that restarted its stream counts from 1 again: its
            // records are stale, and the count says so.
            return Err(sensor_error(format!(
                "the F/T sensor at {:?} has sent nothing newer than record {} for {age_ms:.1} \
                 ms (`backend.franka.net_ft.timeout_ms` = {}; {} stale records dropped)",
                self.cfg.address,
                self.last_sequence.unwrap_or(0),
                self.cfg.timeout_ms,
                self.stale
            )));
        }
        Ok(self.wrench)
    }

    /// Drops every record that has arrived without taking it, and starts
    /// the time-out at `now_ns`: called when the motion starts, so that the
    /// loop's first reads are of records sent since, not of those queued
    /// since [`NetFt::connect`] (the socket's buffer keeps the oldest when
    /// it fills). Never blocks or allocates.
    pub fn discard_queued(&mut self, now_ns: u64) {
        let mut buf = [0u8; 64];
        while self.socket.recv(&mut buf).is_ok() {}
        self.last_ns = now_ns;
    }

    /// Records taken, and datagrams that were not a record.
    pub fn counts(&self) -> (u64, u64) {
        (self.records, self.malformed)
    }

    /// Records dropped because their sequence was not newer than the last
    /// one taken (replayed or reordered).
    pub fn stale(&self) -> u64 {
        self.stale
    }

    /// The tare: what the readings are taken relative to, N and N·m.
    pub fn bias(&self) -> [f64; 6] {
        self.bias
    }
}

impl Drop for NetFt {
    fn drop(&mut self) {
        // Stops the stream; a lost stop leaves the sensor streaming to a
        // closed port, which is harmless.
        let _ = self.socket.send(&request(CMD_STOP, 0));
    }
}

#[cfg(test)]
mod tests {
    //! Against a sensor stand-in on the loopback interface that speaks
    //! the manual's RDT format (no Net F/T is reachable here; docs/franka.md
    //! says what has and has not been run).
    use super::*;

    fn cfg(address: String) -> NetFtConfig {
        NetFtConfig {
            address,
            counts_per_force: 1_000_000.0,
            counts_per_torque: 2_000_000.0,
            timeout_ms: 10.0,
            start_timeout_s: 10.0,
            tare_ms: 0.0,
        }
    }

    /// The fault code and reason of a sensor error.
    fn fault(e: HardwareError) -> (u32, String) {
        match e {
            HardwareError::Robot { code, reason } => (code, reason),
            e => panic!("not a sensor fault: {e:?}"),
        }
    }

    fn record(seq: u32, status: u32, counts: [i32; 6]) -> Record {
        Record {
            rdt_sequence: seq,
            ft_sequence: seq * 3,
            status,
            counts,
        }
    }

    /// A stand-in sensor: waits for the start request, then sends `records`.
    fn sensor(records: Vec<Record>) -> (String, std::thread::JoinHandle<[u8; 8]>) {
        let s = UdpSocket::bind("127.0.0.1:0").unwrap();
        let addr = s.local_addr().unwrap().to_string();
        let h = std::thread::spawn(move || {
            let mut buf = [0u8; 16];
            let (n, from) = s.recv_from(&mut buf).unwrap();
            assert_eq!(n, 8, "a request is 8 bytes");
            for r in records {
                s.send_to(&r.to_bytes(), from).unwrap();
            }
            // A datagram that is not a record.
            s.send_to(&[1, 2, 3], from).unwrap();
            let mut req = [0u8; 8];
            req.copy_from_slice(&buf[..8]);
            req
        });
        (addr, h)
    }

    #[test]
    fn requests_and_records_are_the_manuals_bytes() {
        assert_eq!(request(CMD_START, 0), [0x12, 0x34, 0, 2, 0, 0, 0, 0]);
        assert_eq!(request(CMD_STOP, 0), [0x12, 0x34, 0, 0, 0, 0, 0, 0]);
        let r = record(7, 0, [1, -2, 3, -4, 5, -6]);
        let b = r.to_bytes();
        assert_eq!(&b[0..4], &[0, 0, 0, 7]);
        assert_eq!(&b[16..20], &(-2i32).to_be_bytes());
        assert_eq!(Record::parse(&b), Some(r));
        assert_eq!(Record::parse(&b[..35]), None);
    }

    #[test]
    fn the_newest_record_becomes_the_wrench_in_newtons() {
        let (addr, h) = sensor(vec![
            record(1, 0, [0; 6]),
            record(2, 0, [1_500_000, -250_000, 9_810_000, 200_000, -400_000, 0]),
        ]);
        let mut ft = NetFt::connect(&cfg(addr), 0).unwrap();
        assert_eq!(h.join().unwrap(), request(CMD_START, 0));
        // The stand-in has sent everything (joined): a blocking wait for
        // the rest is not needed, but UDP on loopback may still be in
        // flight; read until the second record is in.
        let mut w = ft.read(1_000_000).unwrap();
        for _ in 0..1000 {
            if ft.counts().0 == 2 && ft.counts().1 == 1 {
                break;
            }
            std::thread::sleep(Duration::from_millis(1));
            w = ft.read(1_000_000).unwrap();
        }
        assert_eq!(ft.counts(), (2, 1), "records, malformed");
        let want = [1.5, -0.25, 9.81, 0.1, -0.2, 0.0];
        for (a, b) in w.iter().zip(want) {
            assert!((a - b).abs() < 1e-12, "{w:?}");
        }
        // Silent past the time-out (10 ms after the newest record): a
        // Fault naming the sensor, on the loop's clock, not the machine's.
        let e = ft.read(1_000_000 + 11_000_000).unwrap_err();
        let (code, reason) = fault(e);
        assert_eq!(code, FAULT_FT_SENSOR);
        assert!(reason.contains("has sent nothing"), "{reason}");
    }

    #[test]
    fn records_queued_before_the_motion_are_discarded() {
        let (addr, h) = sensor(vec![record(1, 0, [0; 6]), record(2, 0, [5; 6])]);
        let mut ft = NetFt::connect(&cfg(addr), 0).unwrap();
        h.join().unwrap();
        // Wait (bounded) until the rest has arrived, without taking it.
        let mut buf = [0u8; 64];
        let start = Instant::now();
        while ft.socket.peek(&mut buf).is_err() {
            assert!(start.elapsed() < Duration::from_secs(10), "nothing queued");
            std::thread::sleep(Duration::from_millis(1));
        }
        std::thread::sleep(Duration::from_millis(20));
        ft.discard_queued(50_000_000);
        assert_eq!(ft.counts(), (1, 0), "nothing taken by the discard");
        // Nothing new after it: silent once the time-out has passed since
        // the discard, not since the connection.
        assert!(ft.read(55_000_000).is_ok());
        let e = ft.read(61_000_000).unwrap_err();
        assert!(e.to_string().contains("has sent nothing"), "{e}");
    }

    /// A stand-in that sends `first` after the start request, then `later`
    /// when told (the returned sender), then stops.
    fn sensor_in_two(
        first: Vec<Record>,
        later: Vec<Record>,
    ) -> (
        String,
        std::sync::mpsc::Sender<()>,
        std::thread::JoinHandle<()>,
    ) {
        let s = UdpSocket::bind("127.0.0.1:0").unwrap();
        let addr = s.local_addr().unwrap().to_string();
        let (tx, rx) = std::sync::mpsc::channel::<()>();
        let h = std::thread::spawn(move || {
            let mut buf = [0u8; 16];
            let (_, from) = s.recv_from(&mut buf).unwrap();
            for r in first {
                s.send_to(&r.to_bytes(), from).unwrap();
            }
            if rx.recv().is_ok() {
                for r in later {
                    s.send_to(&r.to_bytes(), from).unwrap();
                }
            }
        });
        (addr, tx, h)
    }

    /// Reads at `now_ns` until `done` holds (bounded: loopback UDP may
    /// still be in flight).
    fn read_until(ft: &mut NetFt, now_ns: u64, done: impl Fn(&NetFt) -> bool) -> [f64; 6] {
        let start = Instant::now();
        loop {
            let w = ft.read(now_ns).unwrap();
            if done(ft) {
                return w;
            }
            assert!(
                start.elapsed() < Duration::from_secs(10),
                "{:?}",
                ft.counts()
            );
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    #[test]
    fn replayed_and_reordered_records_are_dropped_and_do_not_count_as_the_sensor_speaking() {
        let a = [1_000_000, 0, 0, 0, 0, 0];
        let (addr, tx, h) = sensor_in_two(
            vec![record(1, 0, [0; 6]), record(2, 0, a)],
            // A replay of record 2 with other values, then record 1 again.
            vec![record(2, 0, [7_000_000; 6]), record(1, 0, [9_000_000; 6])],
        );
        let mut ft = NetFt::connect(&cfg(addr), 0).unwrap();
        let w = read_until(&mut ft, 1_000_000, |f| f.counts().0 == 2);
        assert_eq!(w[0], 1.0);
        tx.send(()).unwrap();
        h.join().unwrap();
        let w = read_until(&mut ft, 5_000_000, |f| f.stale() == 2);
        assert_eq!(
            w,
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            "the replays change nothing"
        );
        assert_eq!(ft.counts(), (2, 0));
        // Silent since record 2 (taken at 1 ms), although datagrams came at
        // 5 ms: the time-out (10 ms) runs from the newest record taken.
        let e = ft.read(11_500_000).unwrap_err();
        assert!(e.to_string().contains("has sent nothing"), "{e}");
    }

    #[test]
    fn sequences_are_compared_across_the_counters_wrap() {
        assert!(is_newer(1, 0));
        assert!(is_newer(0, u32::MAX));
        assert!(is_newer(3, u32::MAX - 2));
        assert!(!is_newer(5, 5));
        assert!(!is_newer(4, 5));
        assert!(!is_newer(u32::MAX, 0));
    }

    #[test]
    fn the_rest_reading_at_start_up_is_taken_off_later_readings() {
        let rest = [2_000_000, -1_000_000, 30_000_000, 400_000, 0, -200_000];
        let contact = [
            2_500_000, -1_000_000, 35_000_000, 400_000, 100_000, -200_000,
        ];
        // Five rest records that differ (Fx 1.6 .. 2.4 N, mean 2 N): the
        // first, taken while connecting, must count once.
        let at_rest = |i: u32| {
            let mut c = rest;
            c[0] += (i as i32 - 3) * 200_000;
            c
        };
        let (addr, tx, h) = sensor_in_two(
            (1..=5).map(|i| record(i, 0, at_rest(i))).collect(),
            vec![record(6, 0, contact)],
        );
        // Without the first: 2.1 N; with it twice: 1.93 N.
        let mut c = cfg(addr);
        c.tare_ms = 200.0;
        let mut ft = NetFt::connect(&c, 0).unwrap();
        // Every rest record arrived within the tare's window.
        assert_eq!(ft.counts().0, 5, "{:?}", ft.counts());
        let want_bias = [2.0, -1.0, 30.0, 0.2, 0.0, -0.1];
        for (b, w) in ft.bias().iter().zip(want_bias) {
            assert!((b - w).abs() < 1e-12, "{:?}", ft.bias());
        }
        tx.send(()).unwrap();
        h.join().unwrap();
        let w = read_until(&mut ft, 1_000_000, |f| f.counts().0 == 6);
        let want = [0.5, 0.0, 5.0, 0.0, 0.05, 0.0];
        for (a, b) in w.iter().zip(want) {
            assert!((a - b).abs() < 1e-12, "{w:?}");
        }
    }

    #[test]
    fn a_record_with_a_fault_status_is_a_fault() {
        let (addr, _h) = sensor(vec![record(1, 0x8001_0000, [0; 6])]);
        let e = NetFt::connect(&cfg(addr), 0).unwrap_err();
        let (code, reason) = fault(e);
        assert_eq!(code, FAULT_FT_SENSOR);
        assert!(reason.contains("0x80010000"), "{reason}");
    }

    #[test]
    fn a_sensor_that_never_answers_is_named() {
        // A bound socket that reads nothing.
        let quiet = UdpSocket::bind("127.0.0.1:0").unwrap();
        let mut c = cfg(quiet.local_addr().unwrap().to_string());
        c.start_timeout_s = 0.3;
        let e = NetFt::connect(&c, 0).unwrap_err();
        let (code, reason) = fault(e);
        assert_eq!(code, FAULT_FT_SENSOR);
        assert!(reason.contains("sent no record"), "{reason}");
        assert!(reason.contains("net_ft.address"), "{reason}");
    }
}
