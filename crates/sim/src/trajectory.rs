//! Attitude trajectories: where the sensor points at each sample, and how fast it turns.

use magcal_calib::frames::{self, Mat3};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use rand::RngExt;

/// The attitude at one sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// Time, s.
    pub t_s: f64,
    /// Attitude quaternion `[w, x, y, z]`, sensor → NED.
    pub quat: [f64; 4],
    /// Angular rate in sensor axes, rad/s.
    pub omega_rad_s: [f64; 3],
    /// Where the sensor is, NED, m (the tumble wanders about the origin; the jig and the turntable stay there).
    pub position_m: [f64; 3],
}

/// How the sensor is turned during the recording.
#[derive(Clone, Debug, PartialEq)]
pub enum Trajectory {
    /// A smooth random tumble through all orientations: the body rate on each axis is a sum of random sinusoids
    /// (0.02–0.3 Hz) scaled to the given RMS rate; the start attitude is random.
    Tumble {
        /// Length, s.
        duration_s: f64,
        /// RMS of the body rate's magnitude, rad/s (a hand turning a sensor: ~1).
        rate_rad_s: f64,
    },
    /// The 24 static poses of a cube jig ([`cube24_poses`]), each held for `dwell_s`, with `transition_s` between
    /// poses during which nothing is recorded.
    Cube24 {
        /// Time held in each pose, s.
        dwell_s: f64,
        /// Time between poses, s.
        transition_s: f64,
    },
    /// A single-axis turntable: the sensor turns about the world's down axis at a constant rate, its own axes tilted
    /// from NED by `tilt_deg` about north.
    Turntable {
        /// Length, s.
        duration_s: f64,
        /// Turn rate, degrees/s.
        rate_deg_s: f64,
        /// Tilt of the sensor on the table, degrees.
        tilt_deg: f64,
    },
}

impl Trajectory {
    /// The routine's name, as in the recording's `routine` metadata.
    pub fn routine(&self) -> &'static str {
        match self {
            Trajectory::Tumble { .. } => "free",
            Trajectory::Cube24 { .. } => "cube24",
            Trajectory::Turntable { .. } => "turntable",
        }
    }

    /// The poses at `rate_hz`, drawing the random parts from `rng`.
    pub fn poses(&self, rate_hz: f64, rng: &mut impl RngExt) -> Vec<Pose> {
        let dt = 1.0 / rate_hz;
        match *self {
            Trajectory::Tumble {
                duration_s,
                rate_rad_s,
            } => tumble(duration_s, rate_rad_s, dt, rng),
            Trajectory::Cube24 {
                dwell_s,
                transition_s,
            } => {
                let per_pose = (dwell_s * rate_hz).round().max(1.0) as usize;
                let mut out = Vec::with_capacity(24 * per_pose);
                for (p, pose) in cube24_poses().iter().enumerate() {
                    let t0 = p as f64 * (dwell_s + transition_s);
                    out.extend((0..per_pose).map(|i| Pose {
                        t_s: t0 + i as f64 * dt,
                        quat: pose.quat,
                        omega_rad_s: [0.0; 3],
                        position_m: [0.0; 3],
                    }));
                }
                out
            }
            Trajectory::Turntable {
                duration_s,
                rate_deg_s,
                tilt_deg,
            } => {
                let n = (duration_s * rate_hz).round() as usize;
                let tilt =
                    UnitQuaternion::from_axis_angle(&Vector3::x_axis(), tilt_deg.to_radians());
                let rate = rate_deg_s.to_radians();
                (0..n)
                    .map(|i| {
                        let t = i as f64 * dt;
                        let yaw = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), rate * t);
                        let q = yaw * tilt;
                        // ω in sensor axes: the world rate about down, seen from the sensor.
                        let w = q.inverse_transform_vector(&Vector3::new(0.0, 0.0, rate));
                        Pose {
                            t_s: t,
                            quat: to_array(&q),
                            omega_rad_s: [w.x, w.y, w.z],
                            position_m: [0.0; 3],
                        }
                    })
                    .collect()
            }
        }
    }
}

pub(crate) fn to_array(q: &UnitQuaternion<f64>) -> [f64; 4] {
    [q.w, q.i, q.j, q.k]
}

/// Sinusoids per axis in the tumble's body rate.
const TUMBLE_TONES: usize = 4;
/// Integration sub-steps per sample.
pub(crate) const TUMBLE_SUBSTEPS: usize = 4;

/// The tumble's body rate: per axis a sum of random sinusoids, scaled to an RMS rate. Shared by the batch
/// [`Trajectory::Tumble`] and the bench's virtual hand.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct TumbleRate {
    /// Per axis, `(frequency Hz, phase rad)` of each tone.
    tones: [[(f64, f64); TUMBLE_TONES]; 3],
    /// Amplitude of every tone, rad/s.
    amp_rad_s: f64,
}

impl TumbleRate {
    /// Draws the tones (0.02–0.3 Hz, random phases) for an RMS body rate of `rate_rad_s`.
    pub(crate) fn draw(rate_rad_s: f64, rng: &mut impl RngExt) -> TumbleRate {
        let tones = std::array::from_fn(|_| {
            std::array::from_fn(|_| {
                (
                    rng.random_range(0.02..0.3),
                    rng.random_range(0.0..std::f64::consts::TAU),
                )
            })
        });
        // Each tone contributes a²/2 to the axis' mean square; three axes of four tones make |ω|² = 6a².
        let amp_rad_s = rate_rad_s / (3.0 * TUMBLE_TONES as f64 / 2.0).sqrt();
        TumbleRate { tones, amp_rad_s }
    }

    /// The body rate at `t_s`, rad/s in sensor axes.
    pub(crate) fn omega(&self, t_s: f64) -> Vector3<f64> {
        Vector3::from_fn(|k, _| {
            self.tones[k]
                .iter()
                .map(|(f, phi)| self.amp_rad_s * (std::f64::consts::TAU * f * t_s + phi).sin())
                .sum()
        })
    }

    /// Turns `q` by the body rate from `t_s` over `dt_s`, in `substeps` midpoint steps (second-order accurate).
    pub(crate) fn advance(
        &self,
        q: &mut UnitQuaternion<f64>,
        t_s: f64,
        dt_s: f64,
        substeps: usize,
    ) {
        let h = dt_s / substeps as f64;
        for s in 0..substeps {
            // Body rates compose on the right.
            let wm = self.omega(t_s + (s as f64 + 0.5) * h);
            *q *= UnitQuaternion::from_scaled_axis(wm * h);
        }
    }
}

/// A uniformly random start attitude (a normalised random quaternion).
pub(crate) fn random_attitude(rng: &mut impl RngExt) -> UnitQuaternion<f64> {
    let start = Quaternion::new(
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
    );
    UnitQuaternion::from_quaternion(start)
}

/// Sinusoids per axis of the tumble's wander through the room.
const WANDER_TONES: usize = 3;
/// RMS of the wander per axis, m: a sensor turned in the hand moves about the bench too.
const WANDER_RMS_M: f64 = 0.15;

/// Where a hand-held sensor is: per axis a sum of slow random sinusoids (0.01–0.1 Hz) about the origin.
struct Wander {
    tones: [[(f64, f64); WANDER_TONES]; 3],
}

impl Wander {
    fn draw(rng: &mut impl RngExt) -> Wander {
        Wander {
            tones: std::array::from_fn(|_| {
                std::array::from_fn(|_| {
                    (
                        rng.random_range(0.01..0.1),
                        rng.random_range(0.0..std::f64::consts::TAU),
                    )
                })
            }),
        }
    }

    fn at(&self, t_s: f64) -> [f64; 3] {
        // Each tone contributes a²/2 to the axis' mean square.
        let amp = WANDER_RMS_M / (WANDER_TONES as f64 / 2.0).sqrt();
        std::array::from_fn(|k| {
            self.tones[k]
                .iter()
                .map(|(f, phi)| amp * (std::f64::consts::TAU * f * t_s + phi).sin())
                .sum()
        })
    }
}

fn tumble(duration_s: f64, rate_rad_s: f64, dt: f64, rng: &mut impl RngExt) -> Vec<Pose> {
    let rate = TumbleRate::draw(rate_rad_s, rng);
    let mut q = random_attitude(rng);
    // Drawn after the attitude's parts, so that the turning is what it was before positions existed.
    let wander = Wander::draw(rng);
    let n = (duration_s / dt).round() as usize;
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let t = i as f64 * dt;
        let w = rate.omega(t);
        out.push(Pose {
            t_s: t,
            quat: to_array(&q),
            omega_rad_s: [w.x, w.y, w.z],
            position_m: wander.at(t),
        });
        rate.advance(&mut q, t, dt, TUMBLE_SUBSTEPS);
    }
    out
}

/// One pose of the cube jig: which face is down, where the sensor's +X points, and the attitude that gives.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CubePose {
    /// The sensor face resting on the bench, e.g. `"−Z"` (the sensor's +Z axis points up).
    pub face_down: &'static str,
    /// The horizontal direction the sensor's reference edge points to, e.g. `"north"`.
    pub heading: &'static str,
    /// Attitude quaternion `[w, x, y, z]`, sensor → NED.
    pub quat: [f64; 4],
}

/// The 24 static poses of a cube jig against a reference edge aligned with north: each of the six faces down, at
/// four headings (the reference edge is the sensor's +X axis, or +Z when X is vertical).
pub fn cube24_poses() -> Vec<CubePose> {
    // Faces by the sensor axis pointing DOWN (NED +D): e.g. "−Z down" means the −Z face rests on the bench, so +Z
    // points up and the sensor axis pointing down is −Z.
    let faces: [(&str, [f64; 3], [f64; 3]); 6] = [
        ("−Z", [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]),
        ("+Z", [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]),
        ("−X", [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
        ("+X", [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
        ("−Y", [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]),
        ("+Y", [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]),
    ];
    let headings: [(&str, f64); 4] = [
        ("north", 0.0),
        ("east", 90.0),
        ("south", 180.0),
        ("west", 270.0),
    ];
    let mut out = Vec::with_capacity(24);
    for (face, down_axis, edge_axis) in faces {
        for (heading, yaw_deg) in headings {
            // The sensor axis `down_axis` maps to NED down; `edge_axis` maps to the heading's horizontal direction.
            let yaw = yaw_deg.to_radians();
            let edge_world = [yaw.cos(), yaw.sin(), 0.0];
            let down_world = [0.0, 0.0, 1.0];
            let third_sensor = frames::cross(down_axis, edge_axis);
            let third_world = frames::cross(down_world, edge_world);
            // R maps sensor basis vectors (down_axis, edge_axis, third) to (down_world, edge_world, third_world).
            let mut r: Mat3 = [[0.0; 3]; 3];
            for (s, w) in [
                (down_axis, down_world),
                (edge_axis, edge_world),
                (third_sensor, third_world),
            ] {
                for i in 0..3 {
                    for j in 0..3 {
                        r[i][j] += w[i] * s[j];
                    }
                }
            }
            let m = nalgebra::Matrix3::from_fn(|i, j| r[i][j]);
            let q = UnitQuaternion::from_rotation_matrix(
                &nalgebra::Rotation3::from_matrix_unchecked(m),
            );
            out.push(CubePose {
                face_down: face,
                heading,
                quat: to_array(&q),
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stream_rng;

    #[test]
    fn the_cube_poses_are_24_distinct_rotations_with_the_named_face_down() {
        let poses = cube24_poses();
        assert_eq!(poses.len(), 24);
        for (i, p) in poses.iter().enumerate() {
            let r = frames::quat_to_matrix(p.quat);
            // Down in sensor axes is the named face's axis.
            let down_sensor = frames::mat_t_vec(&r, [0.0, 0.0, 1.0]);
            let axis = match &p.face_down[p.face_down.len() - 1..] {
                "X" => 0,
                "Y" => 1,
                _ => 2,
            };
            let sign = if p.face_down.starts_with('−') {
                -1.0
            } else {
                1.0
            };
            assert!((down_sensor[axis] - sign).abs() < 1e-12, "{p:?}");
            for q in &poses[..i] {
                let dot: f64 = (0..4).map(|k| p.quat[k] * q.quat[k]).sum();
                assert!(dot.abs() < 0.99, "duplicate pose {p:?}");
            }
        }
    }

    #[test]
    fn the_tumble_rate_matches_the_attitude_change() {
        let traj = Trajectory::Tumble {
            duration_s: 30.0,
            rate_rad_s: 1.0,
        };
        let poses = traj.poses(100.0, &mut stream_rng(1, 0));
        // Finite-difference the attitude and compare with the reported body rate.
        for w in poses.windows(2).step_by(97) {
            let q0 = UnitQuaternion::from_quaternion(Quaternion::new(
                w[0].quat[0],
                w[0].quat[1],
                w[0].quat[2],
                w[0].quat[3],
            ));
            let q1 = UnitQuaternion::from_quaternion(Quaternion::new(
                w[1].quat[0],
                w[1].quat[1],
                w[1].quat[2],
                w[1].quat[3],
            ));
            let rate = (q0.inverse() * q1).scaled_axis() / 0.01;
            let mid = Vector3::from(w[0].omega_rad_s);
            assert!(
                (rate - mid).norm() < 0.05 * mid.norm().max(0.2),
                "{rate} vs {mid}"
            );
        }
        let rms = (poses
            .iter()
            .map(|p| Vector3::from(p.omega_rad_s).norm_squared())
            .sum::<f64>()
            / poses.len() as f64)
            .sqrt();
        assert!((0.4..2.0).contains(&rms), "{rms}");
    }

    #[test]
    fn the_turntable_keeps_its_axis() {
        let traj = Trajectory::Turntable {
            duration_s: 10.0,
            rate_deg_s: 36.0,
            tilt_deg: 0.0,
        };
        for p in traj.poses(10.0, &mut stream_rng(1, 0)) {
            let w = p.omega_rad_s;
            assert!(
                w[0].abs() < 1e-12
                    && w[1].abs() < 1e-12
                    && (w[2] - 36f64.to_radians()).abs() < 1e-12
            );
        }
    }
}
