//! MAVLink 2 signing as PX4 does it (`mavlink_sign_control.cpp`, `Mavlink::handle_message`).
//!
//! - Without a key, everything is accepted (signed frames too, unchecked) and nothing is
//!   signed.
//! - With a key, a frame is accepted when its signature is authentic and fresh (the
//!   stream rules of [`ringswarm_wire::signing::Signing`]); unsigned frames only for
//!   HEARTBEAT, RADIO_STATUS, ADSB_VEHICLE and COLLISION. Everything sent is signed, with
//!   PX4's link ids (the GCS link is instance 0, the offboard/API link instance 1).
//! - SETUP_SIGNING, whatever its target: refused while armed ("MAVLink signing: rejected
//!   while armed"). A non-blank key (or a non-zero initial timestamp) is taken, with its
//!   initial timestamp. A blank key with timestamp 0 disables signing, but only in a
//!   signed frame (a frame that got this far with a key set is signed unless something
//!   let it through unsigned). Each outcome is reported in a STATUSTEXT and the new key
//!   in a [`VehicleEvent::SigningChanged`] for the driver to store.
//! - The key and the clock survive a reboot; the stream table does not.

use mavlink::dialects::common::{MavSeverity, SETUP_SIGNING_DATA};
use ringswarm_wire::codec::Frame;
use ringswarm_wire::signing::{PX4_UNSIGNED_ALLOWED, Signing, SigningKey};

use super::{LinkId, Vehicle, VehicleEvent};

/// What ArduPilot takes unsigned on a signed link: RADIO_STATUS (109) and RADIO (166).
const ARDUPILOT_UNSIGNED_ALLOWED: [u32; 2] = [109, 166];
use crate::keystore::StoredKey;

impl Vehicle {
    /// The link id of `link` in signatures: PX4's MAVLink instance number (the GCS link
    /// is instance 0), ArduPilot's channel number (the offboard link is SERIAL0,
    /// channel 0).
    pub(super) fn signing_link_id(&self, link: LinkId) -> u8 {
        match (self.is_ardupilot(), link) {
            (false, LinkId::Gcs) | (true, LinkId::Offboard) => 0,
            (false, LinkId::Offboard) | (true, LinkId::Gcs) => 1,
        }
    }

    /// Whether a decoded frame on `link` passes the signing rules; a refusal is counted.
    /// ArduPilot takes everything unsigned on channel 0 (its USB port, "assumed secure":
    /// SITL's SERIAL0, the offboard link here) and elsewhere only RADIO_STATUS and RADIO
    /// unsigned (`GCS_Signing.cpp`); PX4 its own list.
    pub(super) fn admit(&mut self, frame: &Frame, link: LinkId) -> bool {
        let ardupilot = self.is_ardupilot();
        let Some(signing) = self.io.signing.as_mut() else {
            return true;
        };
        if ardupilot && link == LinkId::Offboard && frame.signature.is_none() {
            return true;
        }
        let allowed: &[u32] = if ardupilot {
            &ARDUPILOT_UNSIGNED_ALLOWED
        } else {
            &PX4_UNSIGNED_ALLOWED
        };
        match signing.accept(&frame.stamp(), allowed) {
            Ok(()) => true,
            Err(why) => {
                if frame.signature.is_some() {
                    self.counters.signature_refused += 1;
                } else {
                    self.counters.unsigned_refused += 1;
                }
                tracing::debug!(sysid = self.cfg.system_id, %why, "frame refused");
                false
            }
        }
    }

    /// The key the vehicle signs with now and its clock, if signing is on.
    pub fn signing_key(&self) -> Option<StoredKey> {
        self.io.signing.as_ref().map(|s| StoredKey {
            key: s.key().clone(),
            timestamp: s.timestamp(),
        })
    }

    /// SETUP_SIGNING, already admitted; `signed` says whether its frame was signed.
    pub(super) fn on_setup_signing(&mut self, m: &SETUP_SIGNING_DATA, signed: bool) {
        if self.modes.armed() {
            let text = if self.is_ardupilot() {
                "ERROR: Won't setup signing when armed"
            } else {
                "MAVLink signing: rejected while armed"
            };
            self.send_statustext(MavSeverity::MAV_SEVERITY_CRITICAL, text);
            return;
        }
        let key = SigningKey::from_bytes(m.secret_key);
        if m.initial_timestamp == 0 && key.is_blank() {
            if self.io.signing.is_none() {
                self.send_statustext(MavSeverity::MAV_SEVERITY_INFO, "MAVLink signing disabled");
                return;
            }
            if !signed {
                self.send_statustext(
                    MavSeverity::MAV_SEVERITY_CRITICAL,
                    "MAVLink signing: blank key rejected",
                );
                return;
            }
            // The statustext goes out signed: the peer that turned signing off still
            // holds the key.
            self.send_statustext(MavSeverity::MAV_SEVERITY_INFO, "MAVLink signing disabled");
            self.io.signing = None;
            self.events.push_back(VehicleEvent::SigningChanged(None));
            return;
        }
        self.io.signing = Some(Signing::new(key.clone(), m.initial_timestamp));
        self.send_statustext(
            MavSeverity::MAV_SEVERITY_INFO,
            "MAVLink signing key accepted",
        );
        self.events
            .push_back(VehicleEvent::SigningChanged(Some(StoredKey {
                key,
                timestamp: m.initial_timestamp,
            })));
    }
}
