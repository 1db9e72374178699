//! Sensors: what the machine measures of itself (resolvers, pressures, odometry) and the range sensor
//! that scans the terrain. Noise comes from a seeded RNG so a run is reproducible for a seed; the
//! `pressure_sensor_offset` and `resolver_offset` hidden effects act here.

use planner::kinematics::wrap_angle;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

pub use firmware_bridge::scan::{Scan, ScanRequest, SensorPose};

use planner::terrain::TerrainGrid;

use crate::soil_contact::World;

/// Sensor noise and resolution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorSpec {
    /// Resolver resolution: 14 bits per turn (rad).
    pub angle_quantum_rad: f64,
    /// Resolver noise, standard deviation (rad).
    pub angle_noise_rad: f64,
    /// Rate noise, standard deviation (rad/s).
    pub rate_noise_rad_per_s: f64,
    /// Pressure transducer noise, standard deviation (Pa).
    pub pressure_noise_pa: f64,
    /// Pressure transducer full scale (Pa); readings are clamped to `[0, full scale]`.
    pub pressure_full_scale_pa: f64,
    /// Track odometry resolution (m).
    pub odometry_quantum_m: f64,
    /// Range-sensor noise along the ray, standard deviation (m).
    pub range_noise_m: f64,
}

impl Default for SensorSpec {
    fn default() -> Self {
        Self {
            angle_quantum_rad: std::f64::consts::TAU / 16384.0,
            angle_noise_rad: 2.0e-4,
            rate_noise_rad_per_s: 2.0e-3,
            pressure_noise_pa: 5.0e4,
            pressure_full_scale_pa: 60.0e6,
            odometry_quantum_m: 1.0e-3,
            range_noise_m: 0.02,
        }
    }
}

/// One value per measured quantity: what the sensors look at ([`SensedTruth`]) and what they read
/// ([`SensorReadings`]), in the same units.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SensorValues {
    /// `[boom, stick, bucket, swing]` angles (rad).
    pub angles_rad: [f64; 4],
    /// Their rates (rad/s).
    pub rates_rad_per_s: [f64; 4],
    /// Head pressures `[boom, stick, bucket]` (Pa).
    pub head_pa: [f64; 3],
    /// Rod pressures (Pa).
    pub rod_pa: [f64; 3],
    /// Pump gallery pressures (Pa).
    pub pump_pa: [f64; 2],
    /// Track travel `[left, right]` (m).
    pub odometry_m: [f64; 2],
}

/// True values the sensors look at.
pub type SensedTruth = SensorValues;

/// One set of readings (noise, quantisation and sensor effects applied), as the gateway would put them
/// on the bus.
pub type SensorReadings = SensorValues;

/// Sensor offsets (hidden effects).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SensorEffects {
    /// Added to every pressure (Pa).
    pub pressure_offset_pa: f64,
    /// Added to boom, stick and bucket angles (rad).
    pub resolver_offset_rad: f64,
}

/// The machine's sensors with their noise generator.
#[derive(Debug, Clone)]
pub struct Sensors {
    spec: SensorSpec,
    rng: ChaCha8Rng,
    /// Noise distributions of angles, rates, pressures and ranges (`None` for zero noise).
    angle_noise: Option<Normal<f64>>,
    rate_noise: Option<Normal<f64>>,
    pressure_noise: Option<Normal<f64>>,
    range_noise: Option<Normal<f64>>,
}

fn quantise(v: f64, q: f64) -> f64 {
    if q > 0.0 { (v / q).round() * q } else { v }
}

/// Zero-mean normal noise of standard deviation `std` (none when `std` is not positive and finite).
fn normal(std: f64) -> Option<Normal<f64>> {
    if std > 0.0 {
        Normal::new(0.0, std).ok()
    } else {
        None
    }
}

impl Sensors {
    /// Sensors with noise seeded from `seed`.
    pub fn new(spec: SensorSpec, seed: u64) -> Self {
        Self {
            spec,
            rng: ChaCha8Rng::seed_from_u64(seed ^ 0x5E45_0125),
            angle_noise: normal(spec.angle_noise_rad),
            rate_noise: normal(spec.rate_noise_rad_per_s),
            pressure_noise: normal(spec.pressure_noise_pa),
            range_noise: normal(spec.range_noise_m),
        }
    }

    fn noise(rng: &mut ChaCha8Rng, distribution: Option<Normal<f64>>) -> f64 {
        distribution.map_or(0.0, |n| n.sample(rng))
    }

    /// Reads every sensor once.
    pub fn read(&mut self, truth: &SensedTruth, effects: &SensorEffects) -> SensorReadings {
        let s = self.spec;
        let mut r = SensorReadings::default();
        for i in 0..4 {
            let offset = if i < 3 {
                effects.resolver_offset_rad
            } else {
                0.0
            };
            let a = truth.angles_rad[i] + offset + Self::noise(&mut self.rng, self.angle_noise);
            r.angles_rad[i] = wrap_angle(quantise(a, s.angle_quantum_rad));
            r.rates_rad_per_s[i] =
                truth.rates_rad_per_s[i] + Self::noise(&mut self.rng, self.rate_noise);
        }
        let pressure_noise = self.pressure_noise;
        let mut pressure = |p: f64| {
            (p + effects.pressure_offset_pa + Self::noise(&mut self.rng, pressure_noise))
                .clamp(0.0, s.pressure_full_scale_pa)
        };
        for i in 0..3 {
            r.head_pa[i] = pressure(truth.head_pa[i]);
            r.rod_pa[i] = pressure(truth.rod_pa[i]);
        }
        for i in 0..2 {
            r.pump_pa[i] = pressure(truth.pump_pa[i]);
            r.odometry_m[i] = quantise(truth.odometry_m[i], s.odometry_quantum_m);
        }
        r
    }

    /// Scans the terrain from a sensor at `origin` (world) looking along `heading_rad`: the rays of
    /// [`cast_scan`], then the range noise along each ray that hit.
    pub fn scan(
        &mut self,
        world: &World,
        origin: [f64; 3],
        heading_rad: f64,
        request: &ScanRequest,
        time_s: f64,
    ) -> Scan {
        self.add_range_noise(cast_scan(
            &world.terrain,
            origin,
            heading_rad,
            request,
            time_s,
        ))
    }

    /// The scan of `cast` with the range noise drawn along each ray that hit, in ray order (the same
    /// draws whether the rays were cast at once or elsewhere while the sensors went on reading).
    pub fn add_range_noise(&mut self, cast: ScanCast) -> Scan {
        let origin = cast.origin;
        let points = cast
            .hits
            .iter()
            .map(|&(dir, range)| {
                let noisy = (range + Self::noise(&mut self.rng, self.range_noise)).max(0.0);
                [0, 1, 2].map(|k| origin[k] + noisy * dir[k])
            })
            .collect();
        Scan {
            time_s: cast.time_s,
            sensor: SensorPose {
                x_m: origin[0],
                y_m: origin[1],
                z_m: origin[2],
                heading_rad: cast.heading_rad,
            },
            points,
        }
    }
}

/// A scan's rays before noise ([`cast_scan`]): the direction and the range of every ray that hit the
/// terrain, in ray order.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanCast {
    /// Simulated time of the scan, s.
    pub time_s: f64,
    /// The sensor (world), m.
    pub origin: [f64; 3],
    /// The sensor's heading, rad.
    pub heading_rad: f64,
    /// Unit direction (world) and range (m) of each ray that hit.
    pub hits: Vec<([f64; 3], f64)>,
}

/// Casts the rays of `request` from a sensor at `origin` (world) looking along `heading_rad` over
/// `terrain`: the first crossing of the terrain surface is the hit, so nearer terrain occludes what
/// lies behind it. The costly part of a scan, and pure: the real-time simulator runs it off its loop
/// on a copy of the terrain.
pub fn cast_scan(
    terrain: &TerrainGrid,
    origin: [f64; 3],
    heading_rad: f64,
    request: &ScanRequest,
    time_s: f64,
) -> ScanCast {
    let req = request.sanitised();
    let step = 0.5 * terrain.resolution_m();
    let mut hits = Vec::with_capacity(req.azimuth_count * req.elevation_count);
    for ia in 0..req.azimuth_count {
        let fa = if req.azimuth_count > 1 {
            ia as f64 / (req.azimuth_count - 1) as f64
        } else {
            0.5
        };
        let az =
            heading_rad + req.azimuth_min_rad + fa * (req.azimuth_max_rad - req.azimuth_min_rad);
        for ie in 0..req.elevation_count {
            let fe = if req.elevation_count > 1 {
                ie as f64 / (req.elevation_count - 1) as f64
            } else {
                0.5
            };
            let el = req.elevation_min_rad + fe * (req.elevation_max_rad - req.elevation_min_rad);
            let dir = [el.cos() * az.cos(), el.cos() * az.sin(), el.sin()];
            let above = |t: f64| {
                let p = [0, 1, 2].map(|k| origin[k] + t * dir[k]);
                terrain.height_at(p[0], p[1]).map(|h| p[2] - h)
            };
            let mut t_prev = 0.0;
            let mut t = step;
            while t <= req.max_range_m {
                match above(t) {
                    Ok(d) if d <= 0.0 => {
                        // Refine the crossing by bisection.
                        let (mut lo, mut hi) = (t_prev, t);
                        for _ in 0..20 {
                            let mid = 0.5 * (lo + hi);
                            match above(mid) {
                                Ok(d) if d > 0.0 => lo = mid,
                                _ => hi = mid,
                            }
                        }
                        hits.push((dir, hi));
                        break;
                    }
                    Ok(_) => {}
                    Err(_) => break, // left the map: no return
                }
                t_prev = t;
                t += step;
            }
        }
    }
    ScanCast {
        time_s,
        origin,
        heading_rad,
        hits,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Scenario;

    #[test]
    fn readings_are_quantised_noisy_offset_and_reproducible() {
        let truth = SensedTruth {
            angles_rad: [0.3, -1.5, -1.0, 0.2],
            head_pa: [10.0e6; 3],
            ..SensedTruth::default()
        };
        let fx = SensorEffects {
            pressure_offset_pa: 1.0e6,
            resolver_offset_rad: 0.05,
        };
        let mut a = Sensors::new(SensorSpec::default(), 7);
        let mut b = Sensors::new(SensorSpec::default(), 7);
        let ra = a.read(&truth, &fx);
        assert_eq!(ra, b.read(&truth, &fx));
        assert!((ra.angles_rad[0] - 0.35).abs() < 2e-3);
        assert!((ra.angles_rad[3] - 0.2).abs() < 2e-3, "no offset on swing");
        assert!((ra.head_pa[0] - 11.0e6).abs() < 3e5);
        let q = SensorSpec::default().angle_quantum_rad;
        assert!(((ra.angles_rad[1] / q) - (ra.angles_rad[1] / q).round()).abs() < 1e-6);
    }

    #[test]
    fn scan_hits_the_terrain_and_the_face_occludes_the_bench_top_behind() {
        let s = Scenario::default_bench().unwrap();
        let world = World::from_scenario(&s).unwrap();
        let mut sensors = Sensors::new(SensorSpec::default(), 1);
        let scan = sensors.scan(&world, [0.0, 0.0, 3.1], 0.0, &ScanRequest::default(), 0.0);
        assert!(scan.points.len() > 1000);
        for p in &scan.points {
            let h = world.height(p[0], p[1]);
            assert!((p[2] - h).abs() < 0.2, "{p:?} vs {h}");
        }
        // From 3.1 m the bench top (2 m) hides the ground just behind its far edge.
        let low = ScanRequest {
            azimuth_count: 1,
            azimuth_min_rad: 0.0,
            azimuth_max_rad: 0.0,
            elevation_count: 1,
            elevation_min_rad: -0.12,
            elevation_max_rad: -0.12,
            ..ScanRequest::default()
        };
        let hit = sensors.scan(&world, [0.0, 0.0, 3.1], 0.0, &low, 0.0);
        assert_eq!(hit.points.len(), 1);
        assert!(
            hit.points[0][2] > 1.5,
            "hit the bench, not the ground behind: {hit:?}"
        );
    }
}
