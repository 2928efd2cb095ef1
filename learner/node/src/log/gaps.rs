//! Gaps in a log's 1 kHz channels: messages that should be there by the
//! channel's rate and are not, so that a user sees lost data before
//! training on it.
//!
//! A channel is a 1 kHz channel when the median interval between its
//! messages' log times (hardware time) is the control period
//! ([`CONTROL_PERIOD_NS`], within 10 %). An interval longer than 1.5
//! periods is a gap of `round(interval / period) − 1` missing messages.
//! On the raw sensor channel the hardware step and the controller's
//! sequence number of every frame tell more: a step gap whose frames have
//! consecutive sequence numbers was never published (hardware states the
//! controller did not answer), a sequence gap is frames the controller
//! published that the log did not record.

use super::{LogReader, ReadError, topics};
use shared_mem_schema::SensorFrame;
use shared_mem_schema::rates::CONTROL_PERIOD_NS;

/// The gaps of one 1 kHz channel.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ChannelGaps {
    /// The channel.
    pub topic: String,
    /// Messages on it.
    pub messages: u64,
    /// Gaps (runs of consecutive missing messages).
    pub gaps: u64,
    /// Missing messages in all.
    pub missing: u64,
    /// Missing messages of the longest gap.
    pub longest: u64,
    /// Log time of the message before the longest gap, ns.
    pub longest_at_ns: u64,
    /// Sensor channel only: where the missing frames went.
    pub sensor: Option<SensorLoss>,
    /// Sensor channel only: the hardware step of the first frame (the
    /// simulator counts an episode's steps from 0, so a later first step
    /// means the episode's first steps have no frame; not counted as
    /// missing, since a real robot's steps need not start at 0).
    pub first_step: Option<u64>,
}

/// Where the sensor channel's missing frames went, from the frames' steps
/// and sequence numbers.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SensorLoss {
    /// Hardware steps the controller published no frame for (it never got
    /// the state, or a newer one superseded it).
    pub not_published: u64,
    /// Frames the controller published that the log lacks (lost between
    /// the controller and the logger).
    pub not_recorded: u64,
}

/// How the missing messages between two neighbours were counted.
fn missing_between(dt_ns: u64, period_ns: u64) -> u64 {
    if 2 * dt_ns <= 3 * period_ns {
        0
    } else {
        ((dt_ns + period_ns / 2) / period_ns).saturating_sub(1)
    }
}

/// The gaps in a channel whose messages have log times `times` (sorted),
/// when it is a 1 kHz channel; `None` otherwise (or with fewer than three
/// messages, too few for a rate).
pub fn gaps_by_time(topic: &str, times: &[u64]) -> Option<ChannelGaps> {
    if times.len() < 3 {
        return None;
    }
    let mut intervals: Vec<u64> = times.windows(2).map(|w| w[1] - w[0]).collect();
    let mid = intervals.len() / 2;
    let median = *intervals.select_nth_unstable(mid).1;
    let p = CONTROL_PERIOD_NS;
    if median.abs_diff(p) * 10 > p {
        return None;
    }
    let mut g = ChannelGaps {
        topic: topic.to_string(),
        messages: times.len() as u64,
        ..ChannelGaps::default()
    };
    for w in times.windows(2) {
        g.add(missing_between(w[1] - w[0], p), w[0]);
    }
    Some(g)
}

impl ChannelGaps {
    fn add(&mut self, missing: u64, at_ns: u64) {
        if missing == 0 {
            return;
        }
        self.gaps += 1;
        self.missing += missing;
        if missing > self.longest {
            self.longest = missing;
            self.longest_at_ns = at_ns;
        }
    }
}

/// Counts the sensor channel's gaps frame by frame, as they are logged
/// (the live node) or read back ([`sensor_gaps`]).
#[derive(Debug, Clone)]
pub struct SensorGapCounter {
    gaps: ChannelGaps,
    last: Option<(u64, u64, u64, u64)>,
}

impl Default for SensorGapCounter {
    fn default() -> Self {
        Self {
            gaps: ChannelGaps {
                topic: topics::SENSOR.to_string(),
                sensor: Some(SensorLoss::default()),
                ..ChannelGaps::default()
            },
            last: None,
        }
    }
}

impl SensorGapCounter {
    /// Takes the next frame of the channel.
    pub fn push(&mut self, f: &SensorFrame) {
        let now = (f.header.episode, f.step, f.header.seq, f.header.t_hw_ns);
        let last = self.last.replace(now);
        self.gaps.messages += 1;
        let Some((episode, step, seq, t)) = last else {
            self.gaps.first_step = Some(f.step);
            return;
        };
        if f.header.episode != episode || f.step <= step {
            // Another episode, or the hardware restarted its count: no
            // rate to hold the two against.
            return;
        }
        let missing = f.step - step - 1;
        self.gaps.add(missing, t);
        let loss = self.gaps.sensor.get_or_insert_default();
        let dseq = f.header.seq.wrapping_sub(seq);
        if (1..=missing + 1).contains(&dseq) {
            loss.not_recorded += dseq - 1;
            loss.not_published += missing + 1 - dseq;
        } else {
            // The controller restarted (its count began again): the
            // frames are missing, where they went is unknown.
            loss.not_published += missing;
        }
    }

    /// What was counted so far.
    pub fn gaps(&self) -> &ChannelGaps {
        &self.gaps
    }
}

/// The gaps of the sensor channel from its frames (in log order): by
/// hardware step, split by the controller's sequence numbers.
pub fn sensor_gaps(frames: &[SensorFrame]) -> ChannelGaps {
    let mut c = SensorGapCounter::default();
    for f in frames {
        c.push(f);
    }
    c.gaps
}

/// The gaps of every 1 kHz channel of a log, the sensor channel first.
pub fn log_gaps(r: &LogReader) -> Result<Vec<ChannelGaps>, ReadError> {
    let mut out = Vec::new();
    for t in r.topics() {
        if t.topic == topics::SENSOR {
            // Frames of another schema version cannot be read: fall back to
            // their log times below.
            if let Ok(frames) = r.read_raw::<SensorFrame>(topics::SENSOR, None) {
                if frames.len() >= 2 {
                    out.insert(0, sensor_gaps(&frames));
                }
                continue;
            }
        }
        let times: Vec<u64> = r
            .read(&[t.topic.as_str()], None)?
            .iter()
            .map(|m| m.log_time)
            .collect();
        if let Some(g) = gaps_by_time(&t.topic, &times) {
            out.push(g);
        }
    }
    Ok(out)
}

/// The gap report as lines for people: one per 1 kHz channel.
pub fn describe(gaps: &[ChannelGaps]) -> Vec<String> {
    let ms = CONTROL_PERIOD_NS as f64 * 1e-6;
    gaps.iter()
        .map(|g| {
            if g.gaps == 0 {
                return format!(
                    "{}: no gaps in {} messages{}",
                    g.topic,
                    g.messages,
                    first_step(g)
                );
            }
            let mut line = format!(
                "{}: {} gaps, {} messages missing ({:.2} % of {}), the longest {} missing (an \
                 interval of {:.0} ms, after log time {:.3} s)",
                g.topic,
                g.gaps,
                g.missing,
                100.0 * g.missing as f64 / (g.messages + g.missing) as f64,
                g.messages + g.missing,
                g.longest,
                (g.longest + 1) as f64 * ms,
                g.longest_at_ns as f64 * 1e-9
            );
            if let Some(s) = g.sensor {
                line.push_str(&format!(
                    "; {} hardware steps without a controller frame, {} frames published but \
                     not recorded",
                    s.not_published, s.not_recorded
                ));
            }
            line.push_str(&first_step(g));
            line
        })
        .collect()
}

/// The note on a sensor channel that begins after step 0.
fn first_step(g: &ChannelGaps) -> String {
    match g.first_step {
        Some(k) if k > 0 => format!("; the first frame is of hardware step {k}"),
        _ => String::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use shared_mem_schema::Message;

    fn frame(step: u64, seq: u64) -> SensorFrame {
        let mut f = *SensorFrame::boxed_zeroed();
        f.header.episode = 1;
        f.header.seq = seq;
        f.header.t_hw_ns = step * CONTROL_PERIOD_NS;
        f.step = step;
        f
    }

    #[test]
    fn sensor_gaps_tell_unpublished_from_unrecorded_frames() {
        // Steps 0..=3, then 4 and 5 never answered (seq goes on by one),
        // then 7 and 8 published (seq 6, 7) but not recorded, then 9.
        let frames = [
            frame(0, 1),
            frame(1, 2),
            frame(2, 3),
            frame(3, 4),
            frame(6, 5),
            frame(9, 8),
        ];
        let g = sensor_gaps(&frames);
        assert_eq!((g.gaps, g.missing, g.longest), (2, 4, 2));
        assert_eq!(
            g.sensor,
            Some(SensorLoss {
                not_published: 2,
                not_recorded: 2
            })
        );
        let lines = describe(&[g]);
        assert!(lines[0].contains("2 gaps, 4 messages missing"), "{lines:?}");
    }

    #[test]
    fn time_gaps_only_for_1khz_channels() {
        let p = CONTROL_PERIOD_NS;
        let mut times: Vec<u64> = (0..100).map(|k| k * p + k % 2).collect();
        times.retain(|t| !(10 * p..15 * p).contains(t));
        let g = gaps_by_time("/tf", &times).unwrap();
        assert_eq!((g.gaps, g.missing, g.longest), (1, 5, 5));
        assert_eq!(g.longest_at_ns, 9 * p + 1);
        // A 20 Hz channel is not one.
        let slow: Vec<u64> = (0..100).map(|k| k * 50 * p).collect();
        assert!(gaps_by_time("/camera/rgbd", &slow).is_none());
    }
}
