//! What the autopilot flies: the airframe and its mechanical state, the air and ground
//! around it (steady wind with first-order Gauss-Markov gusts), and the battery that
//! feeds the motors (drain with thrust, voltage sag as it empties). The autopilot hands
//! it motor thrusts; it reads no parameter and sends nothing.

use nalgebra::{Vector3, Vector4};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use super::config::WindConfig;
use crate::physics::{Airframe, BodyState, Environment};
use crate::profile::GRAVITY_MPS2;

/// The battery's charge and draw.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Battery {
    pub(super) consumed_mah: f64,
    pub(super) current_a: f64,
}

/// The vehicle as physics sees it.
#[derive(Debug, Clone)]
pub(super) struct Plant {
    pub(super) frame: Airframe,
    /// Position (local NED from the start point), velocity, attitude, rates, motors.
    pub(super) state: BodyState,
    /// The wind it flies in and the ground below (local NED).
    pub(super) env: Environment,
    pub(super) battery: Battery,
    wind: WindConfig,
    /// The fraction of its thrust an empty pack takes from the motors.
    battery_sag: f64,
    gust_ned_mps: Vector3<f64>,
    /// The gusts' random source.
    rng: ChaCha8Rng,
}

impl Plant {
    pub(super) fn new(
        frame: Airframe,
        state: BodyState,
        ground_z_ned_m: f64,
        wind: WindConfig,
        battery_sag: f64,
        seed: u64,
    ) -> Self {
        Self {
            frame,
            state,
            env: Environment {
                wind_ned_mps: wind.steady_ned_mps,
                ground_z_ned_m,
            },
            battery: Battery {
                consumed_mah: 0.0,
                current_a: 0.0,
            },
            wind,
            battery_sag,
            gust_ned_mps: Vector3::zeros(),
            rng: ChaCha8Rng::seed_from_u64(seed),
        }
    }

    /// One step of `dt_s`: the wind moves, the motors give what they are asked for times
    /// `available` (the battery's sag), the body moves, the battery drains (`armed`: the
    /// motors draw with thrust; disarmed: the idle draw).
    pub(super) fn advance(
        &mut self,
        motors_n: &Vector4<f64>,
        available: f64,
        armed: bool,
        dt_s: f64,
    ) {
        self.update_wind(dt_s);
        let motors = motors_n * available;
        self.frame
            .advance(&mut self.state, &motors, &self.env, dt_s);
        self.update_battery(armed, dt_s);
    }

    /// The land detector: touching the ground and slower than 0.5 m/s.
    pub(super) fn on_ground(&self) -> bool {
        self.frame.on_ground(&self.state, &self.env) && self.state.vel_ned_mps.norm() < 0.5
    }

    /// Height of the body above the ground (m).
    pub(super) fn height_m(&self) -> f64 {
        self.env.ground_z_ned_m - self.state.pos_ned_m.z
    }

    fn update_wind(&mut self, dt_s: f64) {
        let w = self.wind;
        if w.gust_std_mps > 0.0 {
            let a = (-dt_s / w.gust_tau_s).exp();
            let b = w.gust_std_mps * (1.0 - a * a).sqrt();
            let noise = Vector3::from_fn(|_, _| self.rng.sample::<f64, _>(StandardNormal));
            self.gust_ned_mps = self.gust_ned_mps * a + noise * b;
        }
        self.env.wind_ned_mps = w.steady_ned_mps + self.gust_ned_mps;
    }

    fn update_battery(&mut self, armed: bool, dt_s: f64) {
        let p = self.frame.profile();
        let thrust: f64 = self.state.motor_thrust_n.sum();
        let hover = p.mass_kg * GRAVITY_MPS2;
        let hover_current_a = 7.5 * p.mass_kg;
        self.battery.current_a = if armed {
            // (thrust / hover)^1.5, without powf at 1 kHz.
            let r = (thrust / hover).max(0.0);
            0.5 + hover_current_a * r * r.sqrt()
        } else {
            0.3
        };
        self.battery.consumed_mah += self.battery.current_a * dt_s / 3.6;
    }

    /// The fraction of its thrust the battery's voltage still gives the motors, for a
    /// pack of `capacity_mah`.
    pub(super) fn thrust_available(&self, capacity_mah: f64) -> f64 {
        let used = (self.battery.consumed_mah / capacity_mah).clamp(0.0, 1.0);
        1.0 - self.battery_sag * used
    }

    /// Charge left (%) of a pack of `capacity_mah`.
    pub(super) fn battery_remaining_pct(&self, capacity_mah: f64) -> f64 {
        (100.0 * (1.0 - self.battery.consumed_mah / capacity_mah)).clamp(0.0, 100.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::profile::Profile;

    fn hovering(wind: WindConfig, sag: f64) -> Plant {
        let profile = Profile::x500();
        let mut state = BodyState::at_rest(Vector3::new(0.0, 0.0, -10.0));
        state.motor_thrust_n = Vector4::repeat(profile.mass_kg * GRAVITY_MPS2 / 4.0);
        Plant::new(Airframe::new(profile), state, 0.0, wind, sag, 7)
    }

    fn hover_thrusts(plant: &Plant) -> Vector4<f64> {
        Vector4::repeat(plant.frame.profile().mass_kg * GRAVITY_MPS2 / 4.0)
    }

    #[test]
    fn the_battery_draws_the_hover_current_armed_and_the_idle_current_disarmed() {
        let mut plant = hovering(WindConfig::default(), 0.0);
        let m = plant.frame.profile().mass_kg;
        let motors = hover_thrusts(&plant);
        plant.advance(&motors, 1.0, true, 0.001);
        // At hover thrust (ratio 1): 0.5 A plus 7.5 A per kg.
        let hover_a = 0.5 + 7.5 * m;
        assert!((plant.battery.current_a - hover_a).abs() < 0.05 * hover_a);
        let mut idle = hovering(WindConfig::default(), 0.0);
        for _ in 0..1000 {
            idle.advance(&Vector4::zeros(), 1.0, false, 0.001);
        }
        // 0.3 A for 1 s: 0.3 / 3.6 mAh.
        assert!((idle.battery.consumed_mah - 0.3 / 3.6).abs() < 1e-9);
        assert!((idle.battery_remaining_pct(1.0) - 100.0 * (1.0 - 0.3 / 3.6)).abs() < 1e-9);
    }

    #[test]
    fn an_emptying_pack_sags_by_its_share_used() {
        let mut plant = hovering(WindConfig::default(), 0.2);
        assert_eq!(plant.thrust_available(5000.0), 1.0);
        plant.battery.consumed_mah = 2500.0;
        assert!((plant.thrust_available(5000.0) - 0.9).abs() < 1e-12);
        plant.battery.consumed_mah = 9000.0;
        assert!((plant.thrust_available(5000.0) - 0.8).abs() < 1e-12);
        assert_eq!(plant.battery_remaining_pct(5000.0), 0.0);
    }

    #[test]
    fn gusts_are_zero_mean_with_the_configured_spread_around_the_steady_wind() {
        let wind = WindConfig {
            steady_ned_mps: Vector3::new(2.0, -1.0, 0.0),
            gust_std_mps: 0.5,
            gust_tau_s: 0.2,
        };
        let mut plant = hovering(wind, 0.0);
        let motors = hover_thrusts(&plant);
        let (mut sum, mut sum_sq, n) = (0.0, 0.0, 200_000);
        for _ in 0..n {
            plant.advance(&motors, 1.0, true, 0.001);
            let east = plant.env.wind_ned_mps.y - wind.steady_ned_mps.y;
            sum += east;
            sum_sq += east * east;
        }
        // 200 s over a 0.2 s correlation time: about 500 independent samples, so the
        // mean within 4 standard errors (4 · 0.5 / √500 ≈ 0.09) and the spread within 15 %.
        let mean = sum / f64::from(n);
        let std = (sum_sq / f64::from(n) - mean * mean).sqrt();
        assert!(mean.abs() < 0.09, "mean {mean}");
        assert!((std - 0.5).abs() < 0.075, "std {std}");
    }

    #[test]
    fn without_gusts_the_wind_is_the_steady_wind_and_the_ground_is_below() {
        let wind = WindConfig {
            steady_ned_mps: Vector3::new(3.0, 0.0, 0.0),
            gust_std_mps: 0.0,
            gust_tau_s: 1.0,
        };
        let mut plant = hovering(wind, 0.0);
        let motors = hover_thrusts(&plant);
        plant.advance(&motors, 1.0, true, 0.001);
        assert_eq!(plant.env.wind_ned_mps, wind.steady_ned_mps);
        assert!((plant.height_m() - 10.0).abs() < 1e-3);
        assert!(!plant.on_ground());
    }
}
