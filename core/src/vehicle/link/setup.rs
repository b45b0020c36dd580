//! What the handshake writes to the vehicle and puts back: the fence upload and the
//! parameter session (setup, then the restore after the disarm), and what their answers
//! and timeouts do to the link.

use ringswarm_wire::time::SimTime;

use super::super::fence_upload::{FenceUpload, UploadAnswer, UploadSend};
use super::super::params::ParamSend;
use super::super::{LinkEvent, Phase};
use super::VehicleLink;
use crate::link::Outgoing;

impl VehicleLink {
    /// A fence answer counts while the handshake streams, addressed to us (or to all).
    pub(super) fn fence_answer_is_ours(&self, target_system: u8) -> bool {
        matches!(self.phase, Phase::Streaming(_))
            && (target_system == 0 || target_system == self.cfg.own_ids.0)
    }

    /// Starts (or starts over) the fence upload if the link has one not yet taken.
    pub(super) fn start_fence_upload(&mut self, now: SimTime) {
        if let Some(send) = self.fence.as_mut().and_then(|f| f.start(now)) {
            self.send_fence(send);
        }
    }

    pub(super) fn send_fence(&mut self, send: UploadSend) {
        let target_system = self.cfg.system_id;
        match send {
            UploadSend::Count(count) => self.queue(Outgoing::FenceCount {
                target_system,
                count,
            }),
            UploadSend::Item { seq, item } => self.queue(Outgoing::FenceItem {
                target_system,
                seq,
                item: &item,
            }),
        }
    }

    pub(super) fn on_fence_answer(&mut self, answer: Option<UploadAnswer>) {
        match answer {
            Some(UploadAnswer::Send(send)) => self.send_fence(send),
            Some(UploadAnswer::Done) => {
                let items = self.fence.as_ref().map_or(0, FenceUpload::len);
                self.events.push_back(LinkEvent::FenceUploaded { items });
            }
            Some(UploadAnswer::Failed(why)) => {
                // Not armed without the fence the configuration asks it to hold.
                self.phase = Phase::Failed;
                self.pending = None;
                let reason = format!("vehicle {}: {why}", self.cfg.system_id);
                self.events.push_back(LinkEvent::Failed(reason));
            }
            Some(UploadAnswer::Ignored) | None => {}
        }
    }

    /// Whether the vehicle may be armed as far as the fence goes: no fence to give, or
    /// the vehicle holds it.
    pub(super) fn fence_ready(&self) -> bool {
        self.fence.as_ref().is_none_or(FenceUpload::done)
    }

    /// A PARAM_VALUE: the restore's while it runs, else the handshake's session while
    /// streaming.
    pub(super) fn on_param_value(&mut self, now: SimTime, name: &str, value: f32) {
        let restoring = self.restore_running();
        let session = if restoring {
            self.restore.as_mut()
        } else if matches!(self.phase, Phase::Streaming(_)) {
            self.params.as_mut()
        } else {
            None
        };
        let Some(session) = session else { return };
        let written = session.changed().len();
        let sends = session.on_value(now, name, value);
        let newly: Vec<(&'static str, f32)> = session.changed()[written..].to_vec();
        for (name, from) in newly {
            self.events.push_back(LinkEvent::ParamWritten {
                name,
                from,
                to: value,
                restored: restoring,
            });
        }
        self.send_params(sends);
        self.on_params_progress();
    }

    /// Whether the restore of what the handshake wrote is under way.
    pub(super) fn restore_running(&self) -> bool {
        self.restore
            .as_ref()
            .is_some_and(|r| !r.done() && r.failure().is_none())
    }

    /// After a parameter answer or timeout: what the session's end means.
    pub(super) fn on_params_progress(&mut self) {
        if let Some(restore) = &self.restore {
            if !self.restore_reported && (restore.done() || restore.failure().is_some()) {
                self.restore_reported = true;
                if let Some(why) = restore.failure() {
                    let text = format!("parameters not put back: {why}");
                    self.events.push_back(LinkEvent::VehicleSays(text));
                }
                if self.phase == Phase::Disarming {
                    self.phase = Phase::Done;
                }
            }
            return;
        }
        let Some(params) = &self.params else { return };
        if let Some(why) = params.failure() {
            let reason = format!("vehicle {}: {why}", self.cfg.system_id);
            self.fail(reason);
            return;
        }
        if params.done() && !self.params_applied {
            let dialect = self.state.dialect();
            let read = |p: &ringswarm_wire::ardupilot::ParamName| params.value(p);
            self.angle_boost = dialect.angle_boost(read);
            self.setpoint_held_s = Some(dialect.setpoint_held_s(read));
            if let Some(hover_throttle) = dialect.reported_hover(read) {
                self.events
                    .push_back(LinkEvent::HoverReported { hover_throttle });
            }
            self.params_applied = true;
        }
    }

    /// Runs the timers of the handshake's parameter session, or of the restore.
    pub(super) fn params_timeout(&mut self, now: SimTime, restore: bool) {
        let session = if restore {
            self.restore.as_mut()
        } else {
            self.params.as_mut()
        };
        let sends = session.map(|p| p.handle_timeout(now)).unwrap_or_default();
        self.send_params(sends);
        self.on_params_progress();
    }

    pub(super) fn send_params(&mut self, sends: Vec<ParamSend>) {
        let target_system = self.cfg.system_id;
        for send in sends {
            match send {
                ParamSend::Read(name) => self.queue(Outgoing::ParamRead {
                    target_system,
                    name,
                }),
                ParamSend::Set { name, value } => self.queue(Outgoing::ParamSet {
                    target_system,
                    name,
                    value,
                }),
            }
        }
    }
}
