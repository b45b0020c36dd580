//! A vehicle CSV's rows: written as text at once ([`Row::write_csv`]), or handed over as
//! numbers in binary ([`push_row`]) and turned into text by the run directory's writer
//! thread ([`to_csv`]), so that neither the decimal formatting nor the attitudes' Euler
//! angles cost the control loop anything.
//!
//! A chunk is a sequence of records, each a tag byte then:
//! - `TEXT`: a `u16` length (little endian) and that many bytes, written as they are;
//! - `ROW`: `t_s`, the swarm's and the link's phase names (a `u8` length and the bytes
//!   each), the attitude and setpoint quaternions (`w, i, j, k`, NaN when unknown) and the
//!   other numbers of [`Row`], each an `f64` (little endian).

use nalgebra::{Quaternion, UnitQuaternion};

use super::fixed;

const TEXT: u8 = 0;
const ROW: u8 = 1;

/// One row of a vehicle's CSV (see `CSV_HEADER` for the columns and units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Row<'a> {
    /// Flight time (s).
    pub t_s: f64,
    /// The swarm's phase.
    pub swarm_phase: &'a str,
    /// The vehicle link's phase.
    pub link_phase: &'a str,
    /// Position, then velocity, in the common ENU frame (m, m/s).
    pub state_enu: [f64; 6],
    /// Reported attitude, body FRD to NED, as `[w, i, j, k]` (NaN: none reported yet).
    pub attitude_wijk: [f64; 4],
    /// Commanded acceleration, ENU (m/s²).
    pub command_enu_mps2: [f64; 3],
    /// Attitude setpoint, body FRD to NED, as `[w, i, j, k]`.
    pub setpoint_wijk: [f64; 4],
    /// Normalised thrust setpoint (0..1).
    pub thrust_norm: f64,
    /// Time since the vehicle was last heard (ms; NaN: never).
    pub heard_age_ms: f64,
}

/// Appends text written as it is (a header line).
pub fn push_text(raw: &mut Vec<u8>, text: &str) {
    for piece in text.as_bytes().chunks(usize::from(u16::MAX)) {
        raw.push(TEXT);
        raw.extend_from_slice(&(piece.len() as u16).to_le_bytes());
        raw.extend_from_slice(piece);
    }
}

/// Appends a row.
pub fn push_row(raw: &mut Vec<u8>, row: &Row) {
    raw.push(ROW);
    raw.extend_from_slice(&row.t_s.to_le_bytes());
    for name in [row.swarm_phase, row.link_phase] {
        let name = &name.as_bytes()[..name.len().min(usize::from(u8::MAX))];
        raw.push(name.len() as u8);
        raw.extend_from_slice(name);
    }
    let numbers = row
        .state_enu
        .iter()
        .chain(&row.attitude_wijk)
        .chain(&row.command_enu_mps2)
        .chain(&row.setpoint_wijk)
        .chain([&row.thrust_norm, &row.heard_age_ms]);
    for x in numbers {
        raw.extend_from_slice(&x.to_le_bytes());
    }
}

/// Reads records back.
struct Reader<'a> {
    raw: &'a [u8],
}

impl<'a> Reader<'a> {
    fn bytes(&mut self, n: usize) -> Option<&'a [u8]> {
        if self.raw.len() < n {
            return None;
        }
        let (head, rest) = self.raw.split_at(n);
        self.raw = rest;
        Some(head)
    }

    fn f64(&mut self) -> Option<f64> {
        let b = self.bytes(8)?;
        Some(f64::from_le_bytes([
            b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7],
        ]))
    }

    fn name(&mut self) -> Option<&'a [u8]> {
        let len = usize::from(*self.bytes(1)?.first()?);
        self.bytes(len)
    }

    fn quaternion(&mut self) -> Option<[f64; 4]> {
        Some([self.f64()?, self.f64()?, self.f64()?, self.f64()?])
    }
}

/// Roll, pitch, yaw (rad) of a `[w, i, j, k]` quaternion; NaN for an unknown one.
fn euler(wijk: [f64; 4]) -> (f64, f64, f64) {
    if wijk.iter().any(|x| x.is_nan()) {
        return (f64::NAN, f64::NAN, f64::NAN);
    }
    let [w, i, j, k] = wijk;
    UnitQuaternion::new_unchecked(Quaternion::new(w, i, j, k)).euler_angles()
}

/// Writes a chunk of records as CSV text (the writer thread's side). A truncated record
/// (never written by [`push_row`] and [`push_text`]) ends the chunk.
pub fn to_csv(raw: &[u8], out: &mut Vec<u8>) {
    let mut r = Reader { raw };
    while let Some(tag) = r.bytes(1) {
        let written = match tag[0] {
            TEXT => r.bytes(2).and_then(|len| {
                let text = r.bytes(usize::from(u16::from_le_bytes([len[0], len[1]])))?;
                out.extend_from_slice(text);
                Some(())
            }),
            ROW => write_row(&mut r, out),
            _ => None,
        };
        if written.is_none() {
            return;
        }
    }
}

fn write_row(r: &mut Reader, out: &mut Vec<u8>) -> Option<()> {
    let t_s = r.f64()?;
    let swarm_phase = std::str::from_utf8(r.name()?).ok()?;
    let link_phase = std::str::from_utf8(r.name()?).ok()?;
    let mut state_enu = [0.0; 6];
    for x in &mut state_enu {
        *x = r.f64()?;
    }
    let row = Row {
        t_s,
        swarm_phase,
        link_phase,
        state_enu,
        attitude_wijk: r.quaternion()?,
        command_enu_mps2: [r.f64()?, r.f64()?, r.f64()?],
        setpoint_wijk: r.quaternion()?,
        thrust_norm: r.f64()?,
        heard_age_ms: r.f64()?,
    };
    row.write_csv(out);
    Some(())
}

impl Row<'_> {
    /// Appends the row as a CSV line (the attitudes as Euler angles).
    pub fn write_csv(&self, out: &mut Vec<u8>) {
        let (roll, pitch, yaw) = euler(self.attitude_wijk);
        let (sp_roll, sp_pitch, _) = euler(self.setpoint_wijk);
        fixed::push(out, self.t_s, 4);
        out.push(b',');
        out.extend_from_slice(self.swarm_phase.as_bytes());
        out.push(b',');
        out.extend_from_slice(self.link_phase.as_bytes());
        let numbers = self
            .state_enu
            .iter()
            .map(|x| (*x, 4))
            .chain([(roll, 5), (pitch, 5), (yaw, 5)])
            .chain(self.command_enu_mps2.iter().map(|x| (*x, 4)))
            .chain([
                (sp_roll, 5),
                (sp_pitch, 5),
                (self.thrust_norm, 4),
                (self.heard_age_ms, 1),
            ]);
        for (x, decimals) in numbers {
            out.push(b',');
            fixed::push(out, x, decimals);
        }
        out.push(b'\n');
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn csv(raw: &[u8]) -> String {
        let mut out = Vec::new();
        to_csv(raw, &mut out);
        String::from_utf8(out).unwrap()
    }

    #[test]
    fn rows_come_out_as_the_columns_with_their_decimals() {
        // Roll 0.1, pitch −0.2, yaw 0.3 rad; setpoint roll 0.05, pitch 0 (which nalgebra's
        // Euler angles give as −0, written "-0.00000" as the standard formatter does).
        let q = UnitQuaternion::from_euler_angles(0.1, -0.2, 0.3);
        let sp = UnitQuaternion::from_euler_angles(0.05, 0.0, 1.0);
        let wijk = |q: UnitQuaternion<f64>| [q.w, q.i, q.j, q.k];
        let mut raw = Vec::new();
        push_text(&mut raw, "header\n");
        push_row(
            &mut raw,
            &Row {
                t_s: 1.25,
                swarm_phase: "consensus",
                link_phase: "flying",
                state_enu: [1.0, -2.5, 50.0, 0.125, 0.0, -0.5],
                attitude_wijk: wijk(q),
                command_enu_mps2: [0.3, -0.4, 0.0],
                setpoint_wijk: wijk(sp),
                thrust_norm: 0.2,
                heard_age_ms: 3.26,
            },
        );
        push_row(
            &mut raw,
            &Row {
                t_s: 2.0,
                swarm_phase: "handshake",
                link_phase: "connecting",
                state_enu: [0.0; 6],
                attitude_wijk: [f64::NAN; 4],
                command_enu_mps2: [0.0; 3],
                setpoint_wijk: wijk(UnitQuaternion::identity()),
                thrust_norm: 0.0,
                heard_age_ms: f64::NAN,
            },
        );
        assert_eq!(
            csv(&raw),
            "header\n\
             1.2500,consensus,flying,1.0000,-2.5000,50.0000,0.1250,0.0000,-0.5000,\
             0.10000,-0.20000,0.30000,0.3000,-0.4000,0.0000,0.05000,-0.00000,0.2000,3.3\n\
             2.0000,handshake,connecting,0.0000,0.0000,0.0000,0.0000,0.0000,0.0000,\
             NaN,NaN,NaN,0.0000,0.0000,0.0000,0.00000,-0.00000,0.0000,NaN\n"
        );
    }

    #[test]
    fn a_truncated_record_ends_the_chunk_without_a_partial_line() {
        let mut raw = Vec::new();
        push_text(&mut raw, "a\n");
        push_text(&mut raw, "b\n");
        assert_eq!(csv(&raw[..raw.len() - 1]), "a\n");
        assert_eq!(csv(&[7, 1, 2]), "");
    }
}
