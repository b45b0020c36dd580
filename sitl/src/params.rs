//! The parameter table: PX4 names, PX4 encoding; or, for the ArduPilot personality,
//! ArduCopter's names and encoding on the wire in front of the PX4 ones the emulated
//! controllers still read (those are not on the wire then).
//!
//! Values travel as MAVLink `float` fields. PX4's integer parameters use its bytewise
//! encoding (`MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE`): the `i32`'s bytes are sent
//! as the float's bytes. ArduPilot's integers travel as their value cast to a float
//! (`MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT`). The profile's physical values are read-only
//! (`SIM_*`): a PARAM_SET on them, or of a value out of range, is answered with the
//! unchanged value, as PX4 does.

use crate::profile::Profile;

/// A parameter's type on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParamKind {
    /// `MAV_PARAM_TYPE_INT32`, bytewise (PX4).
    Int32,
    /// `MAV_PARAM_TYPE_REAL32`.
    Real32,
    /// `MAV_PARAM_TYPE_INT32`, its value cast to a float (ArduPilot).
    Int32Cast,
}

/// One parameter.
#[derive(Debug, Clone, PartialEq)]
pub struct Param {
    /// Name (at most 16 characters).
    pub name: &'static str,
    /// Its type.
    pub kind: ParamKind,
    /// Its value (integers are held exactly in an `f64`).
    pub value: f64,
    /// Admissible range.
    pub range: (f64, f64),
    /// Whether PARAM_SET may change it.
    pub read_only: bool,
}

impl Param {
    /// The value as MAVLink carries it.
    pub fn wire_value(&self) -> f32 {
        match self.kind {
            ParamKind::Real32 | ParamKind::Int32Cast => self.value as f32,
            ParamKind::Int32 => f32::from_ne_bytes((self.value as i32).to_ne_bytes()),
        }
    }

    /// Decodes a wire value for this parameter's type.
    pub fn from_wire(&self, wire: f32) -> f64 {
        match self.kind {
            ParamKind::Real32 => f64::from(wire),
            // ArduPilot rounds a float written to an integer parameter.
            ParamKind::Int32Cast => f64::from(wire).round(),
            ParamKind::Int32 => f64::from(i32::from_ne_bytes(wire.to_ne_bytes())),
        }
    }
}

/// Why a PARAM_SET changed nothing.
#[derive(Debug, Clone, PartialEq)]
pub enum ParamSetError {
    /// No parameter of that name.
    Unknown(String),
    /// The parameter is read-only.
    ReadOnly(&'static str),
    /// The value is not finite or outside the parameter's range.
    OutOfRange {
        /// The parameter.
        name: &'static str,
        /// The value asked for.
        value: f64,
    },
}

/// The vehicle's parameters, in a fixed order (their `param_index`).
#[derive(Debug, Clone, PartialEq)]
pub struct ParamTable {
    params: Vec<Param>,
    /// The first this many are on the wire (listed, read and set by a ground station).
    on_wire: usize,
}

impl ParamTable {
    /// The table for a vehicle with `system_id` and `profile`.
    pub fn new(system_id: u8, profile: &Profile) -> Self {
        use ParamKind::{Int32, Real32};
        let p = |name, kind, value, range, read_only| Param {
            name,
            kind,
            value,
            range,
            read_only,
        };
        let params = vec![
            p(
                "BAT1_CAPACITY",
                Real32,
                battery_capacity_mah(profile),
                (0.0, 1e5),
                false,
            ),
            p("COM_DISARM_LAND", Real32, 2.0, (-1.0, 20.0), false),
            p("COM_DISARM_PRFLT", Real32, 10.0, (-1.0, 60.0), false),
            p("COM_DL_LOSS_T", Int32, 10.0, (5.0, 300.0), false),
            p("COM_FAIL_ACT_T", Real32, 5.0, (0.0, 25.0), false),
            p("COM_OBL_RC_ACT", Int32, 0.0, (0.0, 7.0), false),
            p("COM_OF_LOSS_T", Real32, 1.0, (0.0, 60.0), false),
            p("COM_RC_IN_MODE", Int32, 4.0, (0.0, 4.0), false),
            p("GF_ACTION", Int32, 2.0, (0.0, 5.0), false),
            p("GF_MAX_HOR_DIST", Real32, 0.0, (0.0, 10_000.0), false),
            p("GF_MAX_VER_DIST", Real32, 0.0, (0.0, 10_000.0), false),
            p("GF_SOURCE", Int32, 0.0, (0.0, 1.0), false),
            p(
                "MAV_SYS_ID",
                Int32,
                f64::from(system_id),
                (1.0, 250.0),
                true,
            ),
            p("MIS_TAKEOFF_ALT", Real32, 2.5, (0.0, 1000.0), false),
            p("MPC_ACC_DOWN_MAX", Real32, 3.0, (2.0, 15.0), false),
            p("MPC_ACC_HOR", Real32, 3.0, (2.0, 15.0), false),
            p("MPC_ACC_UP_MAX", Real32, 4.0, (2.0, 15.0), false),
            p("MPC_LAND_ALT1", Real32, 10.0, (0.0, 122.0), false),
            p("MPC_LAND_ALT2", Real32, 5.0, (0.0, 122.0), false),
            p("MPC_LAND_SPEED", Real32, 0.7, (0.1, 5.0), false),
            p(
                "MPC_THR_HOVER",
                Real32,
                profile.hover_throttle(),
                (0.05, 0.95),
                false,
            ),
            p("MPC_THR_MAX", Real32, 1.0, (0.0, 1.0), false),
            p("MPC_THR_MIN", Real32, 0.12, (0.05, 0.5), false),
            p("MPC_THR_XY_MARG", Real32, 0.3, (0.0, 0.5), false),
            p("MPC_TILTMAX_AIR", Real32, 45.0, (20.0, 89.0), false),
            p("MPC_TKO_RAMP_T", Real32, 3.0, (0.0, 5.0), false),
            p("MPC_TKO_SPEED", Real32, 1.5, (1.0, 5.0), false),
            p("MPC_XY_CRUISE", Real32, 5.0, (3.0, 20.0), false),
            p("MPC_XY_P", Real32, 0.95, (0.0, 2.0), false),
            p("MPC_XY_VEL_D_ACC", Real32, 0.2, (0.0, 2.0), false),
            p("MPC_XY_VEL_I_ACC", Real32, 0.4, (0.0, 60.0), false),
            p("MPC_XY_VEL_MAX", Real32, 12.0, (0.0, 20.0), false),
            p("MPC_XY_VEL_P_ACC", Real32, 1.8, (1.2, 5.0), false),
            p("MPC_YAWRAUTO_MAX", Real32, 60.0, (5.0, 360.0), false),
            p("MPC_Z_P", Real32, 1.0, (0.1, 1.5), false),
            p("MPC_Z_VEL_D_ACC", Real32, 0.0, (0.0, 2.0), false),
            p("MPC_Z_VEL_I_ACC", Real32, 2.0, (0.2, 3.0), false),
            p("MPC_Z_VEL_MAX_DN", Real32, 1.5, (0.5, 4.0), false),
            p("MPC_Z_VEL_MAX_UP", Real32, 3.0, (0.5, 8.0), false),
            p("MPC_Z_VEL_P_ACC", Real32, 4.0, (2.0, 15.0), false),
            p("MPC_Z_V_AUTO_DN", Real32, 1.5, (0.5, 4.0), false),
            p("MPC_Z_V_AUTO_UP", Real32, 3.0, (0.5, 8.0), false),
            p("NAV_ACC_RAD", Real32, 10.0, (0.05, 200.0), false),
            p("NAV_DLL_ACT", Int32, 0.0, (0.0, 6.0), false),
            p("NAV_MC_ALT_RAD", Real32, 0.8, (0.05, 200.0), false),
            // PX4's multicopter defaults (rc.mc_defaults), not the generic 30/60 m.
            p("RTL_CONE_ANG", Int32, 45.0, (0.0, 90.0), false),
            p("RTL_DESCEND_ALT", Real32, 10.0, (0.0, 500.0), false),
            p("RTL_LAND_DELAY", Real32, 0.0, (-1.0, 300.0), false),
            p("RTL_MIN_DIST", Real32, 10.0, (0.5, 100.0), false),
            p("RTL_RETURN_ALT", Real32, 30.0, (0.0, 1000.0), false),
            p(
                "SIM_DRAG",
                Real32,
                profile.linear_drag_per_s,
                (0.0, 0.0),
                true,
            ),
            p("SIM_IXX", Real32, profile.inertia_kg_m2.x, (0.0, 0.0), true),
            p("SIM_IYY", Real32, profile.inertia_kg_m2.y, (0.0, 0.0), true),
            p("SIM_IZZ", Real32, profile.inertia_kg_m2.z, (0.0, 0.0), true),
            p("SIM_MASS", Real32, profile.mass_kg, (0.0, 0.0), true),
            p(
                "SIM_MOT_TAU",
                Real32,
                profile.motor_time_constant_s,
                (0.0, 0.0),
                true,
            ),
            p(
                "SIM_THRUST_MAX",
                Real32,
                profile.max_thrust_n(),
                (0.0, 0.0),
                true,
            ),
        ];
        Self {
            on_wire: params.len(),
            params,
        }
    }

    /// The table of the ArduPilot personality: ArduCopter's parameters a ground station
    /// and the coordinator read and write (4.7 names; ArduPilot's defaults, the hover
    /// throttle the profile's), in front of the PX4 table the emulated controllers read.
    pub fn ardupilot(system_id: u8, profile: &Profile) -> Self {
        use ParamKind::{Int32Cast, Real32};
        let p = |name, kind, value, range: (f64, f64)| Param {
            name,
            kind,
            value,
            range,
            read_only: false,
        };
        let mut params = vec![
            // All checks on; the emulator's own are the EKF settle and the mode's.
            p("ARMING_CHECK", Int32Cast, 1.0, (0.0, 1_048_575.0)),
            p("ATC_ANGLE_BOOST", Int32Cast, 1.0, (0.0, 1.0)),
            p("DISARM_DELAY", Int32Cast, 10.0, (0.0, 127.0)),
            p("FENCE_ACTION", Int32Cast, 1.0, (0.0, 5.0)),
            p("FENCE_ALT_MAX", Real32, 100.0, (10.0, 1000.0)),
            p("FENCE_ENABLE", Int32Cast, 0.0, (0.0, 1.0)),
            p("FENCE_MARGIN", Real32, 2.0, (1.0, 10.0)),
            p("FENCE_TYPE", Int32Cast, 7.0, (0.0, 15.0)),
            p("FS_GCS_ENABLE", Int32Cast, 0.0, (0.0, 7.0)),
            p("FS_GCS_TIMEOUT", Real32, 5.0, (2.0, 120.0)),
            p("GUID_OPTIONS", Int32Cast, 0.0, (0.0, 255.0)),
            p("GUID_TIMEOUT", Real32, 3.0, (0.1, 5.0)),
            p("MAV_GCS_SYSID", Int32Cast, 255.0, (1.0, 255.0)),
            Param {
                read_only: true, // taken at the next boot only
                ..p("MAV_SYSID", Int32Cast, f64::from(system_id), (1.0, 255.0))
            },
            p(
                "MOT_THST_HOVER",
                Real32,
                profile.hover_throttle(),
                (0.125, 0.6875),
            ),
            p("WPNAV_SPEED_DN", Real32, 150.0, (10.0, 500.0)),
            p("WPNAV_SPEED_UP", Real32, 250.0, (10.0, 1000.0)),
        ];
        let on_wire = params.len();
        params.extend(Self::new(system_id, profile).params);
        Self { params, on_wire }
    }

    /// Number of parameters on the wire (`param_count`).
    pub fn len(&self) -> usize {
        self.on_wire
    }

    /// Whether the table is empty (never, for a vehicle).
    pub fn is_empty(&self) -> bool {
        self.params.is_empty()
    }

    /// The parameter at `index` on the wire.
    pub fn get(&self, index: usize) -> Option<&Param> {
        self.params.get(index).filter(|_| index < self.on_wire)
    }

    /// The index and parameter called `name` on the wire.
    pub fn find_on_wire(&self, name: &str) -> Option<(usize, &Param)> {
        self.find(name).filter(|(i, _)| *i < self.on_wire)
    }

    /// Sets a parameter on the wire from its wire value (as [`ParamTable::set`]).
    ///
    /// # Errors
    /// [`ParamSetError`]; a parameter not on the wire is unknown.
    pub fn set_on_wire(&mut self, name: &str, wire: f32) -> Result<usize, ParamSetError> {
        if self.find_on_wire(name).is_none() {
            return Err(ParamSetError::Unknown(name.to_owned()));
        }
        self.set(name, wire)
    }

    /// The index and parameter called `name`.
    pub fn find(&self, name: &str) -> Option<(usize, &Param)> {
        self.params.iter().enumerate().find(|(_, p)| p.name == name)
    }

    /// The value of a parameter known to exist.
    ///
    /// # Panics
    /// If `name` is not in the table: names are compile-time constants of this crate.
    pub fn value(&self, name: &str) -> f64 {
        self.find(name)
            .map(|(_, p)| p.value)
            .unwrap_or_else(|| panic!("parameter {name} is in the table"))
    }

    /// Sets a parameter from its wire value.
    ///
    /// # Errors
    /// [`ParamSetError`] for an unknown name, a read-only parameter or a value out of range.
    pub fn set(&mut self, name: &str, wire: f32) -> Result<usize, ParamSetError> {
        let index = self
            .find(name)
            .map(|(i, _)| i)
            .ok_or_else(|| ParamSetError::Unknown(name.to_owned()))?;
        let param = &mut self.params[index];
        if param.read_only {
            return Err(ParamSetError::ReadOnly(param.name));
        }
        let value = param.from_wire(wire);
        if !value.is_finite() || value < param.range.0 || value > param.range.1 {
            return Err(ParamSetError::OutOfRange {
                name: param.name,
                value,
            });
        }
        param.value = value;
        Ok(index)
    }
}

/// Battery capacity for a profile: a 4S 5000 mAh pack for the x500 class, scaled by mass.
fn battery_capacity_mah(profile: &Profile) -> f64 {
    (2500.0 * profile.mass_kg).round()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integers_are_bytewise_and_reals_are_floats() {
        let table = ParamTable::new(3, &Profile::x500());
        let (_, sys) = table.find("MAV_SYS_ID").unwrap();
        assert_eq!(sys.wire_value().to_ne_bytes(), 3i32.to_ne_bytes());
        let (_, hover) = table.find("MPC_THR_HOVER").unwrap();
        assert_eq!(hover.wire_value(), 0.5);
    }

    #[test]
    fn ardupilot_shows_its_own_names_with_integers_as_floats() {
        let mut table = ParamTable::ardupilot(4, &Profile::arducopter());
        assert_eq!(table.len(), 17);
        let (_, sys) = table.find_on_wire("MAV_SYSID").unwrap();
        assert_eq!(sys.wire_value(), 4.0);
        let (_, hover) = table.find_on_wire("MOT_THST_HOVER").unwrap();
        assert!((hover.wire_value() - 0.39).abs() < 1e-6);
        // The PX4 parameters the controllers read are there, but not on the wire.
        assert!(table.find("MPC_THR_HOVER").is_some());
        assert!(table.find_on_wire("MPC_THR_HOVER").is_none());
        assert!((0..table.len()).all(|i| table.get(i).is_some()));
        assert!(table.get(table.len()).is_none());
        assert_eq!(
            table.set_on_wire("COM_OF_LOSS_T", 2.0),
            Err(ParamSetError::Unknown("COM_OF_LOSS_T".into()))
        );
        assert!(table.set_on_wire("GUID_OPTIONS", 8.0).is_ok());
        assert_eq!(table.value("GUID_OPTIONS"), 8.0);
        assert_eq!(
            table.set_on_wire("MAV_SYSID", 9.0),
            Err(ParamSetError::ReadOnly("MAV_SYSID"))
        );
    }

    #[test]
    fn set_checks_name_read_only_and_range() {
        let mut table = ParamTable::new(1, &Profile::x500());
        assert!(table.set("COM_OF_LOSS_T", 2.5).is_ok());
        assert_eq!(table.value("COM_OF_LOSS_T"), 2.5);
        let seven = f32::from_ne_bytes(7i32.to_ne_bytes());
        assert!(table.set("COM_OBL_RC_ACT", seven).is_ok());
        assert_eq!(table.value("COM_OBL_RC_ACT"), 7.0);
        assert_eq!(
            table.set("SIM_MASS", 3.0),
            Err(ParamSetError::ReadOnly("SIM_MASS"))
        );
        assert_eq!(
            table.set("NOPE", 1.0),
            Err(ParamSetError::Unknown("NOPE".into()))
        );
        assert!(matches!(
            table.set("COM_OF_LOSS_T", f32::NAN),
            Err(ParamSetError::OutOfRange { .. })
        ));
    }
}
