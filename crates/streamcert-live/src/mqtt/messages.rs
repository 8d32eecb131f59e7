//! The MQTT source's messages: a row, a signal's value, a bad payload or a retained message
//! taken again, each counted, and acknowledged now or held for the next checkpoint.

use std::time::{Instant, SystemTime, UNIX_EPOCH};

use rumqttc::Publish;
use streamcert_pipeline::RowError;
use streamcert_pipeline::input::Sample;
use streamcert_pipeline::source::Next;

use super::MqttSource;
use crate::config::Layout;
use crate::payload::{PayloadError, parse_row, parse_signal};

impl MqttSource {
    /// One message: a row, a bad payload, or nothing yet (a signal's update, a redelivery);
    /// acknowledged now, or held for the next checkpoint.
    pub(super) fn message(&mut self, p: Publish, s: &mut Sample) -> Option<Next> {
        self.report.messages += 1;
        self.last_message = Instant::now();
        self.poisoned = false;
        if let Some(seen) = self.topics.iter_mut().find(|(t, _)| rumqttc::matches(&p.topic, t)) {
            seen.1 = true;
        }
        let next = if p.retain && self.report.retained_again(&p.topic, &p.payload) {
            self.report.redelivered += 1;
            None
        } else {
            self.parse(&p, s)
        };
        // Without a checkpoint the client acknowledges each message as it arrives.
        if self.manual_acks {
            self.unacked.push(p);
        }
        next
    }

    /// What a message yields.
    fn parse(&mut self, p: &Publish, s: &mut Sample) -> Option<Next> {
        match &self.cfg.layout {
            Layout::Rows { format, fields, .. } => {
                match parse_row(&p.payload, *format, fields, self.cfg.max_payload, s) {
                    Ok(()) => self.ordered(s.t, p.dup, &p.payload),
                    Err(e) => Some(self.bad(&p.topic, &e)),
                }
            }
            Layout::Signals { signals, .. } => {
                let i = *self.signal_of.get(&p.topic)?;
                let sig = &signals[i];
                let keys = (sig.time_key.as_str(), sig.value_key.as_str());
                match parse_signal(&p.payload, sig.format, keys, now(), self.cfg.max_payload) {
                    Ok((t, v)) => {
                        let rows = self.rows.as_mut()?;
                        if rows.push(i, t, v).is_err() {
                            if p.dup {
                                self.report.redelivered += 1;
                            } else {
                                self.report.late += 1;
                            }
                        }
                        None
                    }
                    Err(e) => Some(self.bad(&p.topic, &e)),
                }
            }
        }
    }

    /// A whole row with time `t`: yielded if after the last, passed over if a redelivery,
    /// bad otherwise.
    fn ordered(&mut self, t: f64, dup: bool, payload: &[u8]) -> Option<Next> {
        match self.last_t {
            Some(last) if t <= last && dup => {
                self.report.redelivered += 1;
                None
            }
            Some(last) if t <= last => {
                let what = format!("time {t} is not after the previous row's {last}");
                let e = PayloadError::new("time_backwards", &what, payload);
                Some(self.bad("", &e))
            }
            _ => {
                self.last_t = Some(t);
                self.report.rows += 1;
                Some(Next::Row)
            }
        }
    }

    /// A bad payload: counted, named on stderr, yielded.
    fn bad(&mut self, topic: &str, e: &PayloadError) -> Next {
        self.report.count_bad(e.kind);
        let topic = if topic.is_empty() { "(rows)" } else { topic };
        Next::Bad(RowError {
            file: format!("mqtt topic {topic}"),
            line: self.report.messages,
            column: None,
            message: e.to_string(),
        })
    }
}

/// Seconds since the Unix epoch (a bare value's arrival time).
fn now() -> f64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0.0, |d| d.as_secs_f64())
}
