//! Provisioning one vehicle with a signing key over its link (`ringswarm sign-setup`), as
//! a sans-IO machine.
//!
//! Every second, up to [`ATTEMPTS`] times, it sends SETUP_SIGNING (target the vehicle,
//! component 1) twice: unsigned, which a vehicle without a key takes, and signed with the
//! new key, which a vehicle that already holds it takes (PX4 refuses unsigned frames once
//! it has a key). The vehicle has the key once a frame from it is signed with it; PX4's
//! "MAVLink signing: rejected while armed" ends the attempt at once.

use std::time::Duration;

use mavlink::dialects::common::{MavMessage, SETUP_SIGNING_DATA};
use ringswarm_wire::codec::{Encoder, decode_datagram_with};
use ringswarm_wire::signing::{Signing, SigningKey};
use ringswarm_wire::time::SimTime;

/// Sends before giving up.
pub const ATTEMPTS: u32 = 5;

/// Time between sends.
pub const INTERVAL: Duration = Duration::from_secs(1);

/// Where provisioning stands.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ProvisionState {
    /// Sending and waiting.
    Pending,
    /// A frame signed with the key came back.
    Provisioned,
    /// The vehicle said no (its STATUSTEXT).
    Refused(String),
    /// No signed frame after every attempt.
    GaveUp,
}

/// Provisioning of one vehicle.
#[derive(Debug)]
pub struct Provision {
    system_id: u8,
    signing: Signing,
    initial_timestamp: u64,
    encoder: Encoder,
    sent: u32,
    next_send: SimTime,
    state: ProvisionState,
    outbox: Vec<Vec<u8>>,
}

impl Provision {
    /// Provisions vehicle `system_id` with `key`, its clock to start at
    /// `initial_timestamp`; we send as `own_ids` (system, component).
    pub fn new(system_id: u8, key: SigningKey, initial_timestamp: u64, own_ids: (u8, u8)) -> Self {
        Self {
            system_id,
            signing: Signing::new(key, initial_timestamp),
            initial_timestamp,
            encoder: Encoder::new(own_ids.0, own_ids.1),
            sent: 0,
            next_send: SimTime::ZERO,
            state: ProvisionState::Pending,
            outbox: Vec::new(),
        }
    }

    /// Where it stands.
    pub fn state(&self) -> &ProvisionState {
        &self.state
    }

    /// When [`Provision::handle_timeout`] is due next.
    pub fn poll_timeout(&self) -> SimTime {
        self.next_send
    }

    /// Sends the next pair of SETUP_SIGNING, or gives up.
    pub fn handle_timeout(&mut self, now: SimTime) {
        if self.state != ProvisionState::Pending || now < self.next_send {
            return;
        }
        if self.sent == ATTEMPTS {
            self.state = ProvisionState::GaveUp;
            return;
        }
        self.sent += 1;
        self.next_send = now + INTERVAL;
        let msg = MavMessage::SETUP_SIGNING(SETUP_SIGNING_DATA {
            initial_timestamp: self.initial_timestamp,
            target_system: self.system_id,
            target_component: 1,
            secret_key: *self.signing.key().bytes(),
        });
        self.outbox.push(self.encoder.encode(&msg));
        let link_id = 0;
        self.outbox
            .push(self.encoder.encode_signed(&msg, &mut self.signing, link_id));
    }

    /// The next datagram to send.
    pub fn poll_transmit(&mut self) -> Option<Vec<u8>> {
        if self.outbox.is_empty() {
            None
        } else {
            Some(self.outbox.remove(0))
        }
    }

    /// A datagram from the vehicle.
    pub fn handle_datagram(&mut self, bytes: &[u8]) {
        if self.state != ProvisionState::Pending {
            return;
        }
        for frame in decode_datagram_with(bytes, Some(self.signing.key()))
            .into_iter()
            .flatten()
        {
            if frame.system_id() != self.system_id {
                continue;
            }
            if frame.signature.is_some_and(|t| t.authentic) {
                self.state = ProvisionState::Provisioned;
                return;
            }
            if let MavMessage::STATUSTEXT(t) = &frame.msg
                && let Ok(text) = t.text.to_str()
                // PX4: "MAVLink signing: rejected while armed"; ArduPilot: "ERROR: Won't
                // setup signing when armed".
                && (text.contains("rejected") || text.contains("Won't setup signing"))
            {
                self.state = ProvisionState::Refused(text.trim_end_matches('\0').to_owned());
                return;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::dialects::common::{MavSeverity, STATUSTEXT_DATA};

    fn vehicle_frame(key: Option<&SigningKey>, msg: &MavMessage) -> Vec<u8> {
        let mut enc = Encoder::new(3, 1);
        match key {
            Some(k) => enc.encode_signed(msg, &mut Signing::new(k.clone(), 10), 1),
            None => enc.encode(msg),
        }
    }

    #[test]
    fn sends_both_forms_each_second_and_ends_on_a_frame_signed_with_the_key() {
        let key = SigningKey::from_bytes([9; 32]);
        let mut p = Provision::new(3, key.clone(), 1234, (253, 190));
        p.handle_timeout(SimTime::ZERO);
        let first: Vec<_> = std::iter::from_fn(|| p.poll_transmit()).collect();
        let frames: Vec<_> = first
            .iter()
            .map(|b| decode_datagram_with(b, Some(&key)).remove(0).unwrap())
            .collect();
        assert_eq!(frames.len(), 2);
        assert!(frames[0].signature.is_none());
        assert!(frames[1].signature.is_some_and(|t| t.authentic));
        for f in &frames {
            let MavMessage::SETUP_SIGNING(m) = &f.msg else {
                panic!("{:?}", f.msg)
            };
            assert_eq!((m.target_system, m.target_component), (3, 1));
            assert_eq!(m.initial_timestamp, 1234);
            assert_eq!(&m.secret_key, key.bytes());
        }
        assert_eq!(p.poll_timeout(), SimTime::from_millis(1000));
        // An unsigned heartbeat (no key yet) changes nothing; another key's neither.
        let hb = crate::link::gcs_heartbeat();
        p.handle_datagram(&vehicle_frame(None, &hb));
        p.handle_datagram(&vehicle_frame(Some(&SigningKey::from_bytes([8; 32])), &hb));
        assert_eq!(p.state(), &ProvisionState::Pending);
        p.handle_datagram(&vehicle_frame(Some(&key), &hb));
        assert_eq!(p.state(), &ProvisionState::Provisioned);
    }

    #[test]
    fn an_armed_vehicle_refuses_and_a_silent_one_is_given_up_after_five_seconds() {
        let key = SigningKey::from_bytes([9; 32]);
        let mut p = Provision::new(3, key.clone(), 0, (253, 190));
        p.handle_timeout(SimTime::ZERO);
        let text = MavMessage::STATUSTEXT(STATUSTEXT_DATA {
            severity: MavSeverity::MAV_SEVERITY_CRITICAL,
            text: "MAVLink signing: rejected while armed".into(),
            id: 0,
            chunk_seq: 0,
        });
        p.handle_datagram(&vehicle_frame(None, &text));
        assert_eq!(
            p.state(),
            &ProvisionState::Refused("MAVLink signing: rejected while armed".into())
        );
        let mut silent = Provision::new(3, key, 0, (253, 190));
        for s in 0..=5 {
            silent.handle_timeout(SimTime::from_millis(1000 * s));
        }
        assert_eq!(silent.state(), &ProvisionState::GaveUp);
        assert_eq!(std::iter::from_fn(|| silent.poll_transmit()).count(), 10);
    }
}
