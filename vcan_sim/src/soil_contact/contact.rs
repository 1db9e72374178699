//! The bucket in the soil, one contact step at a time: the cutting edge cutting the terrain into the
//! bucket (an exact mass ledger), the bucket's content, its spill and dump, and the soil's force on
//! the bucket as a function of the tip velocity ([`ContactLaw`]).

use planner::kinematics::TipForce;
use planner::machine::GRAVITY_M_PER_S2;
use planner::soil::{DigGeometry, SoilProperties, outward_wedge_share};

use super::fee::layered_failure_force_n;
use super::world::{SoilEffects, World};

/// Mass bookkeeping of the soil that the bucket has moved.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MassLedger {
    /// Mass cut from the terrain (kg).
    pub removed_kg: f64,
    /// Mass that left the bucket again (spill and dump, kg).
    pub spilled_kg: f64,
    /// Volume deposited back on the terrain (m^3).
    pub deposited_m3: f64,
}

/// What the bucket holds.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BucketContent {
    /// Bank volume (m^3).
    pub volume_m3: f64,
    /// Mass (kg).
    pub mass_kg: f64,
}

/// Geometry of the bucket for one contact step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactInput {
    /// Cutting-edge centre in the world `[x, y, z]`.
    pub tip_world: [f64; 3],
    /// Cutting edge in the base frame `[x, z]` (x = distance from the swing axis).
    pub tip_base: [f64; 2],
    /// Bucket pin in the base frame `[x, z]`.
    pub pin_base: [f64; 2],
    /// Tip velocity in the base frame `[vx, vz]`.
    pub tip_velocity_base: [f64; 2],
    /// `bucket_abs`: bucket line (pin -> tip) to the horizontal (rad).
    pub bucket_abs_rad: f64,
    /// Azimuth of the digging plane in the world (rad).
    pub azimuth_rad: f64,
    /// Machine position in the world `[x, y]` (the swing axis).
    pub machine_xy: [f64; 2],
    /// Bucket width (m).
    pub width_m: f64,
    /// Bucket capacity (m^3).
    pub capacity_m3: f64,
}

/// The soil-bucket interaction state.
#[derive(Debug, Clone, Default)]
pub struct SoilContact {
    /// What the bucket holds.
    pub content: BucketContent,
    /// Mass bookkeeping.
    pub ledger: MassLedger,
    last_tip: Option<[f64; 3]>,
    pending_spill_m3: f64,
    pending_at: [f64; 2],
    pending_age_s: f64,
    /// Whether the edge was in the soil in the last step.
    pub in_contact: bool,
}

/// Velocity scale (m/s) over which soil resistance builds up from rest (creep regularisation).
const CREEP_SPEED_M_PER_S: f64 = 0.01;
/// Thickness of the cutting edge (with its teeth) that bears on the soil when it is pushed in tip
/// first, m.
const EDGE_THICKNESS_M: f64 = 0.05;
/// Length of the bucket's back (bottom plate) that bears on the soil when it is pushed in, m.
const BACK_BEARING_LENGTH_M: f64 = 0.25;
/// Boulder contact stiffness (N/m) and damping (N s/m).
const BOULDER_STIFFNESS: f64 = 2.0e7;
const BOULDER_DAMPING: f64 = 2.0e5;

/// The soil's force on the bucket as a function of the tip velocity, for the geometry of one contact
/// step: the FEE failure force (Eq. 18) and the bearing of the edge and of the back, each mobilised
/// from rest over the creep speed (1 cm/s), plus a force that does not depend on the velocity (the
/// boulders). The plant evaluates it at every physics step with the current velocity and takes its
/// velocity gradient implicitly: the mobilisation is a steep damper (force / creep speed, ~1e7 N s/m)
/// that, held explicitly over a 5 ms contact step against the oil column, drove the stick into a
/// 100 Hz limit cycle with load swings of about 1 MN.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ContactLaw {
    /// Fully mobilised FEE failure force (N) for the edge travelling out (`+x`, index 0) and in
    /// (`-x`, index 1): the wedge forms ahead of the edge, so its rake follows the travel.
    pub failure_n: [f64; 2],
    /// Blade direction (edge toward the pin), base frame.
    pub blade: [f64; 2],
    /// `(sin, cos)` of the soil-tool friction angle delta.
    pub friction: (f64, f64),
    /// Fully mobilised bearing force of the edge pushed in tip first (N), along `blade`.
    pub edge_n: f64,
    /// Fully mobilised bearing force of the back pushed in (N), along `opening`.
    pub back_n: f64,
    /// Direction the bucket opening faces, base frame.
    pub opening: [f64; 2],
    /// Force independent of the velocity (boulders; penalty and damping held for the step), N.
    pub held: [f64; 2],
    /// How the wedge's side follows the travel.
    pub travel: TravelSide,
}

/// How the FEE wedge's side follows the edge's travel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TravelSide {
    /// Each side's share of the wedge is [`planner::soil::outward_wedge_share`]'s: the cosine of
    /// the travel's angle from the horizontal, smoothed at rest over the creep speed. An edge moving
    /// straight up or down has half of each side's wedge, and the force turns over smoothly where
    /// the travel does (plant version `implicit-2`).
    #[default]
    Blended,
    /// The whole wedge on the side of `sign(vx)` (plant versions `held-1` and `implicit-1`): the
    /// force turns over in a step at `vx = 0`, which an edge rising through the soil rings across.
    Sign,
}

impl ContactLaw {
    /// The force on the bucket at tip velocity `v` (base frame `[vx, vz]`).
    pub fn force(&self, v: [f64; 2]) -> TipForce {
        let (f, _) = self.evaluate(v, false);
        TipForce {
            fx_n: f[0],
            fz_n: f[1],
            my_nm: 0.0,
        }
    }

    /// `d force / d v` (2 x 2, row = force component, column = velocity component) at `v`.
    pub fn gradient(&self, v: [f64; 2]) -> [[f64; 2]; 2] {
        self.evaluate(v, true).1
    }

    /// Each side's share of the wedge at `v` (out, then in) and their gradients in `v`.
    fn shares(&self, v: [f64; 2]) -> [(f64, [f64; 2]); 2] {
        match self.travel {
            TravelSide::Sign => {
                let out = if v[0] > 0.0 { 1.0 } else { 0.0 };
                [(out, [0.0; 2]), (1.0 - out, [0.0; 2])]
            }
            TravelSide::Blended => {
                let (out, d_out) = outward_wedge_share(v, CREEP_SPEED_M_PER_S);
                [(out, d_out), (1.0 - out, d_out.map(|x| -x))]
            }
        }
    }

    fn evaluate(&self, v: [f64; 2], want_gradient: bool) -> ([f64; 2], [[f64; 2]; 2]) {
        let mut force = self.held;
        let mut grad = [[0.0; 2]; 2];
        let b = self.blade;
        if self.failure_n != [0.0; 2] {
            let (sd, cd) = self.friction;
            let speed = v[0].hypot(v[1]);
            let mobilised = (speed / CREEP_SPEED_M_PER_S).tanh();
            let d_mobilised = (1.0 - mobilised * mobilised) / CREEP_SPEED_M_PER_S;
            let ds = if speed > 1e-12 {
                [v[0] / speed, v[1] / speed]
            } else {
                [0.0, 0.0]
            };
            let shares = self.shares(v);
            for (k, travel_sign) in [1.0, -1.0].into_iter().enumerate() {
                let (share, d_share) = shares[k];
                let f = self.failure_n[k];
                if f == 0.0 || (share == 0.0 && d_share == [0.0; 2]) {
                    continue;
                }
                // The normal into the soil ahead of the edge, on this side.
                let mut n = [b[1], -b[0]];
                if n[0] * travel_sign < 0.0 {
                    n = [-n[0], -n[1]];
                }
                // Eq. 18 on the bucket: against the normal, and up the blade by friction.
                let dir = [-cd * n[0] + sd * b[0], -cd * n[1] + sd * b[1]];
                force[0] += f * share * mobilised * dir[0];
                force[1] += f * share * mobilised * dir[1];
                if want_gradient {
                    let g =
                        [0, 1].map(|c| f * (share * d_mobilised * ds[c] + mobilised * d_share[c]));
                    for r in 0..2 {
                        for c in 0..2 {
                            grad[r][c] += dir[r] * g[c];
                        }
                    }
                }
            }
        }
        // `scale * tanh(s / creep)` along `dir`, with `s` of gradient `ds` in the velocity.
        let mut add = |scale: f64, s: f64, ds: [f64; 2], dir: [f64; 2]| {
            let x = s / CREEP_SPEED_M_PER_S;
            let t = x.tanh();
            force[0] += scale * t * dir[0];
            force[1] += scale * t * dir[1];
            if want_gradient {
                let slope = scale * (1.0 - t * t) / CREEP_SPEED_M_PER_S;
                for r in 0..2 {
                    for c in 0..2 {
                        grad[r][c] += slope * dir[r] * ds[c];
                    }
                }
            }
        };
        let tip_first = -(v[0] * b[0] + v[1] * b[1]);
        if self.edge_n != 0.0 && tip_first > 0.0 {
            add(self.edge_n, tip_first, [-b[0], -b[1]], b);
        }
        let o = self.opening;
        let back_first = -(v[0] * o[0] + v[1] * o[1]);
        if self.back_n != 0.0 && back_first > 0.0 {
            add(self.back_n, back_first, [-o[0], -o[1]], o);
        }
        (force, grad)
    }
}

impl SoilContact {
    /// Moves the edge, cuts the terrain, updates the bucket content and returns the force of the soil
    /// on the bucket (base frame, at the cutting edge).
    pub fn step(
        &mut self,
        world: &mut World,
        input: &ContactInput,
        dt_s: f64,
        effects: &SoilEffects,
    ) -> TipForce {
        self.step_law(world, input, dt_s, effects)
            .force(input.tip_velocity_base)
    }

    /// As [`Self::step`], returning the force as a function of the tip velocity (for the geometry
    /// of this step) instead of its value at `input.tip_velocity_base`.
    pub fn step_law(
        &mut self,
        world: &mut World,
        input: &ContactInput,
        dt_s: f64,
        effects: &SoilEffects,
    ) -> ContactLaw {
        let tip = input.tip_world;
        if !tip.iter().all(|v| v.is_finite()) {
            return ContactLaw::default();
        }
        // 1. Cut along the edge's path and move the material into the bucket.
        if let Some(prev) = self.last_tip {
            self.cut(world, prev, tip, input, effects);
        }
        self.last_tip = Some(tip);

        // Fast path: the edge well above the ground around it and nothing in the bucket to spill.
        let ground = world.height(tip[0], tip[1]);
        if tip[2] > ground + 0.6 && self.content.volume_m3 <= 0.0 && self.pending_spill_m3 <= 0.0 {
            self.in_contact = false;
            world.advance_slopes(dt_s);
            let boulder = self.boulder_force(world, input);
            return ContactLaw {
                held: [boulder.fx_n, boulder.fz_n],
                ..ContactLaw::default()
            };
        }

        // 2. Soil geometry at the edge (Gamma = (d, alpha, rho, V_s)).
        let u = [input.azimuth_rad.cos(), input.azimuth_rad.sin()];
        // Terrain height `offset` metres farther out along the digging plane than the edge.
        let at_r = |offset: f64| world.height(tip[0] + offset * u[0], tip[1] + offset * u[1]);
        let v = input.tip_velocity_base;
        let ahead = if v[0] > 0.0 { 0.15 } else { -0.15 };
        // `at_r(0.0)` is `ground` (the same point on the same terrain).
        let surface = ground.max(at_r(ahead));
        let depth_vertical = surface - tip[2];
        self.in_contact = depth_vertical > 0.0;

        let mut law = ContactLaw::default();
        if self.in_contact {
            let alpha = ((at_r(0.25) - at_r(-0.25)) / 0.5).atan();
            let soil = world.soil_at(tip[0], tip[1], effects);
            // Eq. 17 measures d perpendicular to the terrain.
            let d = depth_vertical * alpha.cos();
            // Blade direction (up from the edge toward the pin) and the normal into the soil ahead.
            let b = [
                input.pin_base[0] - input.tip_base[0],
                input.pin_base[1] - input.tip_base[1],
            ];
            let nb = b[0].hypot(b[1]).max(1e-9);
            let b = [b[0] / nb, b[1] / nb];
            // Rake angle (Fig. 25): between the blade and the terrain surface behind the edge, for
            // either direction of travel.
            let gamma = |travel_sign: f64| {
                let blade_from_travel = b[1].atan2(b[0] * travel_sign);
                let rho = (std::f64::consts::PI - blade_from_travel + alpha * travel_sign)
                    .clamp(0.1, std::f64::consts::PI - 0.1);
                DigGeometry {
                    depth_m: d,
                    slope_rad: alpha,
                    rake_rad: -rho, // the thesis's sign (planner::soil)
                    swept_volume_m3: self.content.volume_m3,
                }
            };
            // The native ground below the floor (layered benches): the share of the cut depth below
            // the floor (the wedge's failure plane runs from the edge up to the surface) and the
            // share of the edge's bearing face below it.
            let native = world.native_soil(effects);
            let (native, below, edge_below) = match native {
                Some((native, floor_m)) if tip[2] < floor_m => (
                    native,
                    ((floor_m - tip[2]) / depth_vertical).clamp(0.0, 1.0),
                    ((floor_m - tip[2]) / EDGE_THICKNESS_M).clamp(0.0, 1.0),
                ),
                _ => (soil, 0.0, 0.0),
            };
            // Without depth below the floor this is the bench soil's failure_force_n.
            let f = [1.0, -1.0].map(|travel_sign| {
                layered_failure_force_n(&soil, &native, below, &gamma(travel_sign), input.width_m)
            });
            // Eq. 18: the tool force on the soil is at delta from the blade normal; on the bucket it is
            // the opposite: against the normal, and up the blade by friction (`ContactLaw`),
            // mobilised from rest over the creep speed. On a layered cut delta is weighted by the
            // share of the blade's contact below the floor.
            let delta = (1.0 - below) * soil.tool_friction_angle_rad
                + below * native.tool_friction_angle_rad;
            law.failure_n = f;
            law.blade = b;
            law.friction = delta.sin_cos();
            // Bearing resistance (bearing pressure c N_c + gamma g d N_q + q0): the cutting edge pushed in
            // tip first (its speed along the bucket line, pin -> tip) bears on its face, bucket width x
            // EDGE_THICKNESS_M, directed back up the blade; the bucket's back (bottom plate) pushed into
            // the soil (speed against the opening) bears over width x BACK_BEARING_LENGTH_M, directed
            // toward the opening. Motion into the opening meets the FEE wedge above. (A plate area for
            // any downward motion stopped a sharp edge at the surface with ~1e5 N.)
            // On a layered cut the native ground bears over the share of the edge's face below the
            // floor (the same share for the back plate, which rides behind the edge).
            let bearing = |s: &SoilProperties| {
                s.cohesion_pa * 40.0
                    + s.density_kg_per_m3 * GRAVITY_M_PER_S2 * d.max(0.0) * 30.0
                    + 2.0e4
            };
            let pressure = if edge_below > 0.0 {
                (1.0 - edge_below) * bearing(&soil) + edge_below * bearing(&native)
            } else {
                bearing(&soil)
            };
            law.edge_n = pressure * input.width_m * EDGE_THICKNESS_M;
            // The opening faces bucket_abs - 90 degrees (as in `spill`).
            let (sa, ca) = input.bucket_abs_rad.sin_cos();
            law.opening = [sa, -ca];
            law.back_n = pressure * input.width_m * BACK_BEARING_LENGTH_M;
        }
        let boulder = self.boulder_force(world, input);
        law.held = [boulder.fx_n, boulder.fz_n];
        // 3. Capacity, spill and dump.
        self.spill(world, input, dt_s);
        // 4. Ground the cuts left steeper than its angle of repose slumps (benches that declare it),
        //    once the edge is out of the soil: while it cuts, the bucket holds the walls around it
        //    and the soil failing ahead of the edge goes into the bucket (the cut and Eq. 17 above),
        //    not into the cells under the bucket behind the edge.
        if !self.in_contact {
            world.advance_slopes(dt_s);
        }
        law
    }

    /// Boulders: a stiff obstacle the edge cannot cut (penalty force along the outward normal).
    fn boulder_force(&self, world: &World, input: &ContactInput) -> TipForce {
        let tip = input.tip_world;
        let u = [input.azimuth_rad.cos(), input.azimuth_rad.sin()];
        let v = input.tip_velocity_base;
        let mut force = [0.0, 0.0];
        for boulder in &world.boulders {
            let rel = [
                tip[0] - boulder.x_m,
                tip[1] - boulder.y_m,
                tip[2] - boulder.z_m,
            ];
            let dist = (rel[0] * rel[0] + rel[1] * rel[1] + rel[2] * rel[2]).sqrt();
            let pen = boulder.radius_m - dist;
            if pen > 0.0 && dist > 1e-9 {
                let normal_h = (rel[0] * u[0] + rel[1] * u[1]) / dist;
                let normal_z = rel[2] / dist;
                let v_n = v[0] * normal_h + v[1] * normal_z;
                let push = (BOULDER_STIFFNESS * pen - BOULDER_DAMPING * v_n).max(0.0);
                force[0] += push * normal_h;
                force[1] += push * normal_z;
            }
        }
        TipForce {
            fx_n: force[0],
            fz_n: force[1],
            my_nm: 0.0,
        }
    }

    fn cut(
        &mut self,
        world: &mut World,
        from: [f64; 3],
        to: [f64; 3],
        input: &ContactInput,
        effects: &SoilEffects,
    ) {
        let t = &world.terrain;
        let res = t.resolution_m();
        let [ox, oy] = t.origin();
        let half = 0.5 * input.width_m + res;
        let xs = [from[0] - half, from[0] + half, to[0] - half, to[0] + half];
        let ys = [from[1] - half, from[1] + half, to[1] - half, to[1] + half];
        let lo_hi = |a: &[f64; 4]| {
            (
                a.iter().copied().fold(f64::INFINITY, f64::min),
                a.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            )
        };
        let ((x0, x1), (y0, y1)) = (lo_hi(&xs), lo_hi(&ys));
        let lowest = world
            .height_known(to[0], to[1])
            .unwrap_or(f64::INFINITY)
            .max(
                world
                    .height_known(from[0], from[1])
                    .unwrap_or(f64::INFINITY),
            );
        // Nothing to cut when the edge stays well above the ground around it.
        if from[2].min(to[2]) > lowest + 0.5 {
            return;
        }
        let i0 = (((x0 - ox) / res).floor().max(0.0) as usize).min(t.nx());
        let i1 = (((x1 - ox) / res).ceil().max(0.0) as usize).min(t.nx());
        let j0 = (((y0 - oy) / res).floor().max(0.0) as usize).min(t.ny());
        let j1 = (((y1 - oy) / res).ceil().max(0.0) as usize).min(t.ny());
        let area = res * res;
        // The native ground of a layered bench has its own density below the floor.
        let native_below = world
            .native_soil
            .filter(|_| from[2].min(to[2]) < world.floor_elevation_m)
            .map(|n| n.density_kg_per_m3);
        let (volume, mass) = if native_below.is_none() && world.default_density_in(i0, i1, j0, j1) {
            // One soil density under the whole edge path: the mass is the removed volume times it.
            let Ok(volume) = world
                .terrain
                .cut(from, to, input.azimuth_rad, input.width_m)
            else {
                return;
            };
            let density = world.default_soil.density_kg_per_m3 + effects.density_kg_per_m3;
            (volume, volume * density)
        } else {
            // The cells whose density differs from the default, with their heights before the cut
            // (rows without any skipped by the summed-area table): the mass is the removed volume
            // times the default density plus, for each of them, its removed volume times the
            // difference (the same mass as summing every cell with its own density, to rounding,
            // without copying the whole box).
            // Below the floor of a layered bench every cell of the box is visited: the part of its
            // removed column below the floor has the native density.
            let nx = t.nx();
            let default_density = world.default_soil.density_kg_per_m3;
            let mut odd = Vec::new();
            for j in j0..j1 {
                if native_below.is_none() && world.default_density_in(i0, i1, j, j + 1) {
                    continue;
                }
                for i in i0..i1 {
                    let excess = world.soil[j * nx + i].density_kg_per_m3 - default_density;
                    if excess != 0.0 || native_below.is_some() {
                        odd.push((i, j, excess, t.cell(i, j).unwrap_or(f64::NAN)));
                    }
                }
            }
            let Ok(volume) = world
                .terrain
                .cut(from, to, input.azimuth_rad, input.width_m)
            else {
                return;
            };
            let mut mass = volume * (default_density + effects.density_kg_per_m3);
            let floor_m = world.floor_elevation_m;
            for (i, j, excess, h0) in odd {
                let h1 = world.terrain.cell(i, j).unwrap_or(h0);
                if h0.is_finite() && h1 < h0 {
                    match native_below {
                        Some(native) => {
                            // The column [h1, h0] splits at the floor: above it the cell's soil,
                            // below it the native ground.
                            let under = (h0.min(floor_m) - h1).max(0.0);
                            mass += (h0 - h1 - under) * area * excess
                                + under * area * (native - default_density);
                        }
                        None => mass += (h0 - h1) * area * excess,
                    }
                }
            }
            (volume, mass)
        };
        if volume > 0.0 {
            world.note_cut(i0, i1, j0, j1);
        }
        self.ledger.removed_kg += mass;
        self.content.volume_m3 += volume;
        self.content.mass_kg += mass;
    }

    fn spill(&mut self, world: &mut World, input: &ContactInput, dt_s: f64) {
        let c = &mut self.content;
        // The opening faces bucket_abs - 90 degrees; it holds while that points up.
        let opening_up = (input.bucket_abs_rad - std::f64::consts::FRAC_PI_2).sin();
        let retention = if self.in_contact {
            1.0
        } else {
            ((opening_up + 0.5) / 1.0).clamp(0.0, 1.0)
        };
        let holdable = input.capacity_m3 * retention;
        if c.volume_m3 > holdable && c.volume_m3 > 0.0 {
            // Overflow while digging is immediate; pouring out in the air takes time.
            let out = if self.in_contact {
                c.volume_m3 - holdable
            } else {
                (c.volume_m3 - holdable).min(3.0 * dt_s.max(0.0))
            };
            let mass = c.mass_kg * out / c.volume_m3;
            c.volume_m3 -= out;
            c.mass_kg -= mass;
            if c.volume_m3 <= 1e-12 {
                // Give the last crumbs' mass to the spill so the ledger closes exactly.
                self.ledger.spilled_kg += c.mass_kg;
                c.volume_m3 = 0.0;
                c.mass_kg = 0.0;
            }
            self.ledger.spilled_kg += mass;
            self.pending_spill_m3 += out;
            self.pending_at = [input.tip_world[0], input.tip_world[1]];
        }
        if self.pending_spill_m3 > 0.0 {
            self.pending_age_s += dt_s.max(0.0);
        }
        // Deposit in batches (a cone fit is costly): 0.05 m^3 or every 0.25 s.
        if self.pending_spill_m3 > 0.05
            || (self.pending_spill_m3 > 0.0 && self.pending_age_s > 0.25)
        {
            self.pending_age_s = 0.0;
            let placed = world.deposit_local(
                self.pending_at[0],
                self.pending_at[1],
                self.pending_spill_m3,
            );
            self.ledger.deposited_m3 += placed;
            self.pending_spill_m3 = 0.0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Boulder;
    use crate::soil_contact::fixtures::*;

    /// Drags the edge toward the machine at height `z` from `x0` for `length_m`; returns the soil
    /// force on the last step and the contact state (content, ledger).
    fn drag(w: &mut World, x0: f64, z: f64, length_m: f64) -> (TipForce, SoilContact) {
        let mut contact = SoilContact::default();
        let effects = SoilEffects::default();
        let mut x = x0;
        let mut f = TipForce::default();
        while x > x0 - length_m {
            f = contact.step(w, &input_at(x, z), 1e-3, &effects);
            x -= 0.0005;
        }
        (f, contact)
    }

    /// A law in the soil: a 45 degree blade, both wedge sides (the outward one the larger, its rake
    /// nearer the wedge's limit), the edge and back bearing.
    fn law_in_soil(travel: TravelSide) -> ContactLaw {
        let b = [
            -std::f64::consts::FRAC_1_SQRT_2,
            std::f64::consts::FRAC_1_SQRT_2,
        ];
        ContactLaw {
            failure_n: [6.0e5, 1.0e5],
            blade: b,
            friction: 0.4f64.sin_cos(),
            edge_n: 1.2e5,
            back_n: 6.0e5,
            opening: [b[1], -b[0]],
            held: [0.0; 2],
            travel,
        }
    }

    /// The gradient the plant's implicit step takes is the force's own, including the turn of the
    /// blended wedge with the travel's direction: central differences at velocities across the
    /// turn (straight up, reversing through rest, near rest, digging in and out).
    #[test]
    fn the_contact_law_gradient_is_the_forces_derivative() {
        let law = law_in_soil(TravelSide::Blended);
        let h = 1e-7;
        for v in [
            [0.0, 0.3],
            [0.004, -0.007],
            [-0.3, 0.1],
            [0.25, -0.05],
            [-0.002, 0.001],
            [0.02, 0.2],
        ] {
            let g = law.gradient(v);
            for c in 0..2 {
                let (mut up, mut down) = (v, v);
                up[c] += h;
                down[c] -= h;
                let (fu, fd) = (law.force(up), law.force(down));
                let numeric = [
                    (fu.fx_n - fd.fx_n) / (2.0 * h),
                    (fu.fz_n - fd.fz_n) / (2.0 * h),
                ];
                for r in 0..2 {
                    let scale = g[r][c].abs().max(numeric[r].abs()).max(1e3);
                    assert!(
                        (g[r][c] - numeric[r]).abs() <= 1e-4 * scale,
                        "v {v:?}: dF{r}/dv{c} {} against {}",
                        g[r][c],
                        numeric[r]
                    );
                }
            }
        }
    }

    /// The blended wedge turns over with the travel's direction: an edge rising straight up meets
    /// half of each side's wedge, one digging in or out at speed nearly all of that side's, and the
    /// force is continuous across `vx = 0` where the sign rule (plants `held-1`, `implicit-1`)
    /// steps.
    #[test]
    fn the_blended_wedge_turns_over_with_the_travel() {
        let blended = law_in_soil(TravelSide::Blended);
        let sign = law_in_soil(TravelSide::Sign);
        let up = blended.shares([0.0, 0.3]);
        assert!((up[0].0 - 0.5).abs() < 1e-12 && (up[1].0 - 0.5).abs() < 1e-12);
        let digging_in = blended.shares([-0.3, 0.02]);
        assert!(digging_in[1].0 > 0.99, "{digging_in:?}");
        let (a, b) = (blended.force([-1e-6, 0.3]), blended.force([1e-6, 0.3]));
        assert!(
            (a.fx_n - b.fx_n).hypot(a.fz_n - b.fz_n) < 100.0,
            "{a:?} {b:?}"
        );
        let (a, b) = (sign.force([-1e-6, 0.3]), sign.force([1e-6, 0.3]));
        assert!(
            (a.fx_n - b.fx_n).hypot(a.fz_n - b.fz_n) > 1.0e5,
            "{a:?} {b:?}"
        );
        // Digging in at speed the two rules agree to the other side's small share.
        let (a, b) = (blended.force([-0.4, 0.0]), sign.force([-0.4, 0.0]));
        assert!((a.fx_n - b.fx_n).hypot(a.fz_n - b.fz_n) < 0.01 * b.fx_n.hypot(b.fz_n) + 1.0);
    }

    /// Done-when: the mass removed from the terrain equals the mass in the bucket plus spill.
    #[test]
    fn mass_removed_equals_bucket_plus_spill() {
        let mut w = world();
        let mut contact = SoilContact::default();
        let effects = SoilEffects::default();
        // Drag the edge 0.6 m deep through the bench face toward the machine, long enough to overfill.
        let mut x = 12.0;
        while x > 7.0 {
            contact.step(&mut w, &input_at(x, 1.2), 1e-3, &effects);
            x -= 0.0005;
        }
        let l = contact.ledger;
        assert!(l.removed_kg > 1000.0, "{l:?}");
        assert!(l.spilled_kg > 0.0, "the bucket overflowed: {l:?}");
        assert!((contact.content.volume_m3 - 1.5).abs() < 1e-6);
        let balance = l.removed_kg - contact.content.mass_kg - l.spilled_kg;
        assert!(balance.abs() < 1e-6 * l.removed_kg, "{balance} kg");
        // Dump: lift out of the soil and open the bucket; everything leaves and is deposited.
        let mut dump = input_at(2.0, 4.0);
        dump.bucket_abs_rad = -0.6;
        for _ in 0..2000 {
            contact.step(&mut w, &dump, 1e-3, &effects);
        }
        assert_eq!(contact.content.mass_kg, 0.0);
        let l = contact.ledger;
        assert!((l.removed_kg - l.spilled_kg).abs() < 1e-6 * l.removed_kg);
    }

    #[test]
    fn soil_resists_a_moving_edge_and_a_boulder_stops_it() {
        let mut w = world();
        let mut contact = SoilContact::default();
        let effects = SoilEffects::default();
        contact.step(&mut w, &input_at(9.0, 1.5), 1e-3, &effects);
        let f = contact.step(&mut w, &input_at(8.9995, 1.5), 1e-3, &effects);
        assert!(
            f.fx_n > 1000.0,
            "soil pushes back against travel toward the machine: {f:?}"
        );
        w.boulders.push(Boulder {
            x_m: 8.0,
            y_m: 0.0,
            z_m: 1.5,
            radius_m: 0.3,
        });
        let f = contact.step(&mut w, &input_at(8.25, 1.5), 1e-3, &effects);
        assert!(f.fx_n > 5.0e5, "{f:?}");
    }

    /// Regression: a bearing force of ~1.1e5 N (a 0.25 m plate under any downward motion) stopped a
    /// sharp edge 1 cm into the bench top, so Autodig could not penetrate. Pushed in tip first the edge
    /// meets only its edge bearing and the shallow FEE wedge; the bucket's back pushed in bears over
    /// the plate.
    #[test]
    fn edge_pushed_in_tip_first_penetrates_but_the_back_bears() {
        let effects = SoilEffects::default();
        let pushed_down = |bucket_abs: f64| {
            let mut w = world();
            let mut contact = SoilContact::default();
            let mut i = input_at(8.0, 1.95);
            i.bucket_abs_rad = bucket_abs;
            i.pin_base = [8.0 - 1.5 * bucket_abs.cos(), 1.95 - 1.5 * bucket_abs.sin()];
            i.tip_velocity_base = [0.0, -0.2];
            contact.step(&mut w, &i, 1e-3, &effects);
            let f = contact.step(&mut w, &i, 1e-3, &effects);
            f.fx_n.hypot(f.fz_n)
        };
        let tip_first = pushed_down(-std::f64::consts::FRAC_PI_2);
        assert!(tip_first > 0.0 && tip_first < 3.0e4, "{tip_first} N");
        let back_first = pushed_down(-std::f64::consts::PI);
        assert!(back_first > 1.0e5, "{back_first} N");
    }

    #[test]
    fn a_dig_with_slumping_keeps_the_ledger_and_the_terrain_volume_exact() {
        let spec = crate::scenario::TerrainSpec {
            repose_deg: Some(45.0),
            ..Default::default()
        };
        let (_, mut w) = extended_world_with(Some(spec));
        let before = sum_heights(&w);
        let area = w.terrain.resolution_m().powi(2);
        let mut contact = SoilContact::default();
        let effects = SoilEffects::default();
        // 0.5 m deep through the face toward the machine (crest at 4 m, toe at 6 m; above the
        // floor, so every cut cell has the bench density), then out.
        let mut x: f64 = 5.4;
        while x > 3.5 {
            let z = (4.0 - x).clamp(-1.4, 0.0) - 0.5;
            contact.step(&mut w, &input_at(x, z), 5e-3, &effects);
            x -= 0.0025;
        }
        let mut out = input_at(3.0, 3.0);
        out.bucket_abs_rad = -0.6;
        for _ in 0..1000 {
            contact.step(&mut w, &out, 5e-3, &effects);
        }
        let l = contact.ledger;
        assert!(l.removed_kg > 500.0, "{l:?}");
        assert!(
            (l.removed_kg - contact.content.mass_kg - l.spilled_kg).abs() < 1e-9 * l.removed_kg
        );
        // Heights summed: what left the terrain is the cut volume less what was deposited back,
        // with the slumps moving material in between.
        let cut_m3 = l.removed_kg / 1700.0;
        let change_m3 = (before - sum_heights(&w)) * area;
        assert!(
            (change_m3 - (cut_m3 - l.deposited_m3)).abs() < 1e-6,
            "{change_m3} vs {cut_m3} - {}",
            l.deposited_m3
        );
        assert!(w.slump.unwrap().dirty.is_none(), "settled within 5 s");
    }

    /// A cut 0.3 m below the floor meets the native ground: harder than the same cut (the same
    /// surface, depth and edge path) where the layer boundary lies below it, and the material it
    /// takes has the native density; a cut entirely above the floor is unchanged by the layer.
    #[test]
    fn a_cut_below_the_floor_is_harder_and_a_cut_above_it_is_unchanged() {
        // On the floor beyond the toe (surface z -2 m), the edge at -2.3 m.
        let (below, below_contact) = drag(&mut extended_world(true, -2.0), 8.0, -2.3, 0.2);
        let (above, above_contact) = drag(&mut extended_world(true, -3.0), 8.0, -2.3, 0.2);
        let (plain, plain_contact) = drag(&mut extended_world(false, -3.0), 8.0, -2.3, 0.2);
        assert!(above.fx_n > 1000.0, "{above:?}");
        assert!(
            below.fx_n > 2.0 * above.fx_n,
            "below the floor {below:?}, above it {above:?}"
        );
        assert_eq!(above, plain);
        // The same volume cut, at the native density below the floor.
        let (vb, va) = (
            below_contact.content.volume_m3,
            above_contact.content.volume_m3,
        );
        assert!(va > 0.05 && (vb - va).abs() < 1e-9, "{vb} vs {va} m^3");
        let density = below_contact.content.mass_kg / vb;
        assert!((density - 2000.0).abs() < 1e-6, "{density} kg/m^3");
        assert!((above_contact.content.mass_kg / va - 1700.0).abs() < 1e-6);
        assert_eq!(above_contact.content, plain_contact.content);
        // Through the face above the floor (x 5 m, z -1.5 m, floor -2 m): the same force, bucket
        // content and terrain with the layer as without it.
        let mut layered = extended_world(true, -2.0);
        let mut single = extended_world(false, -2.0);
        let (a, ac) = drag(&mut layered, 6.0, -1.5, 1.0);
        let (b, bc) = drag(&mut single, 6.0, -1.5, 1.0);
        assert!(ac.content.volume_m3 > 0.1, "{:?}", ac.content);
        assert_eq!(a, b);
        assert_eq!(ac.content, bc.content);
        assert_eq!(ac.ledger, bc.ledger);
        // Mass bookkeeping holds across the layers.
        let l = below_contact.ledger;
        let balance = l.removed_kg - below_contact.content.mass_kg - l.spilled_kg;
        assert!(balance.abs() < 1e-9 * l.removed_kg, "{balance} kg");
    }

    /// A cut that starts in the bench material above the floor and goes below it takes the native
    /// density only for the part below the floor.
    #[test]
    fn a_cut_across_the_floor_splits_its_mass_at_the_floor() {
        // At the toe (x 6 -> 5.6 m: the face from z -2 up to -1.6 m) with the edge at -2.2 m: 0.2 m
        // of native ground under the face material.
        let (_, layered) = drag(&mut extended_world(true, -2.0), 6.0, -2.2, 0.4);
        let (_, single) = drag(&mut extended_world(false, -2.0), 6.0, -2.2, 0.4);
        let v = layered.content.volume_m3;
        assert!((v - single.content.volume_m3).abs() < 1e-9);
        let density = layered.content.mass_kg / v;
        assert!(density > 1750.0 && density < 1990.0, "{density} kg/m^3");
    }
}
