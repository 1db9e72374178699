//! The bucket in the soil: the true terrain (a [`planner::terrain::TerrainGrid`]) with soil properties
//! per cell and hard inclusions, the cutting edge removing material into the bucket, spill and dump
//! back onto the terrain, and the soil force on the bucket.
//!
//! - **Cutting.** Each step the cutting edge (the bucket width, across the digging plane) moves from its
//!   previous to its current world position and every cell above it is lowered to the edge
//!   ([`planner::terrain::TerrainGrid::cut`]). The removed mass is summed cell by cell with each cell's density, so the
//!   ledger is exact: removed = in bucket + spilled ([`MassLedger`]).
//! - **Filling, spill, dump.** The bucket holds up to its capacity while the edge is in the soil; the
//!   excess spills. Out of the soil it holds `capacity x retention(opening angle)`: material pours out
//!   when the opening tips below the horizontal, which is how a dump empties it. Spilled and dumped
//!   material is deposited as a cone at the angle of repose under the bucket.
//! - **Force.** The modified Fundamental Earthmoving Equation for sloped terrain with the swept-volume
//!   surcharge (Eqs. 14-17), `F = d^2 w gamma g N_w + c w d N_c + V_s gamma g N_q`, from
//!   [`planner::soil::fee_force_n`] (the same equations the planner's models use), with the geometry
//!   `Gamma = (d, alpha, rho, V_s)` measured here on the true grid (no section is built). It is directed
//!   at the soil-tool friction angle `delta` from the blade normal (Eq. 18) for either direction of
//!   travel, acting at the cutting edge. The
//!   payload's weight acts at its centroid through the gravity torques (Eq. A4), which replaces the
//!   moment of Eq. 19. Moving down into the ground meets a bearing resistance, and a boulder is a stiff
//!   obstacle the edge cannot cut.
//! - **Layered ground.** A bench may declare the native ground below its floor elevation
//!   (`[native_soil]` in the scenario, [`World::native_soil`]): the compacted ground a bench stands on,
//!   harder than the loosened bench material. When the edge is below the floor the Eq. 17 terms are
//!   split by layer along the wedge of Fig. 25 (`layered_failure_force_n`): with `f` the share of
//!   the cut depth below the floor, the cohesion term (acting along the failure plane, whose length is
//!   proportional to `d`) takes `1 - f` of the bench's `c N_c` and `f` of the native one's; the weight
//!   term (the wedge's area, proportional to `d^2`: the part below the floor is the similar triangle
//!   of depth `f d`) takes `1 - f^2` and `f^2`; the surcharge (the swept bench material, `gamma` of
//!   the bench) is carried across the plane with `N_q` weighted `1 - f`, `f`. The friction angle of
//!   Eq. 18 is weighted by `f`, the edge's bearing takes the native soil over the share of its face
//!   below the floor, and the material cut below the floor has the native density. A cut entirely
//!   above the floor is computed exactly as without the layer.
//!
//! Layout, one concept per module:
//! - `world`: the true terrain with its soil map, layered ground, undulation and boulders ([`World`]);
//! - `slump`: the angle-of-repose relaxation of the bench material near the cuts;
//! - `deposit`: spill and dump cones at the angle of repose;
//! - `fee`: the FEE failure force on the blade, single soil and layered;
//! - `contact`: the bucket in the soil step by step: cutting, content, spill and the force law
//!   ([`SoilContact`], [`ContactLaw`]).

mod contact;
mod deposit;
mod fee;
mod slump;
mod world;

#[cfg(test)]
mod fixtures;

pub use contact::{BucketContent, ContactInput, ContactLaw, MassLedger, SoilContact, TravelSide};
pub use world::{SoilEffects, World};
