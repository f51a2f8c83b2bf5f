//! The uniform grid under the structure contract: one structure, two traversals (`grid` steps
//! every cell, `pc` jumps over empty space with the proximity cloud).

use super::Grid;
use crate::Result;
use crate::accel::contract::{AccelStructure, Walks, dedup_hits};
use crate::accel::{Aabb, AccelParams, Counters, Hit, NoCounters, PACKET, Ray, Resolution, TriAccel, dims_str};

/// The grid's build parameters for this resolution (`res=...`; none for the default): what
/// `--accel grid:res=...` gives, for programs and tests that size a grid by hand.
impl From<Resolution> for AccelParams {
    fn from(r: Resolution) -> Self {
        if r == Resolution::default() {
            AccelParams::NONE
        } else {
            AccelParams::NONE.with("res", r)
        }
    }
}

impl Grid {
    /// The grid's one key of `params`, `res` (`Resolution`'s forms); the default without it.
    pub fn resolution_from(params: &AccelParams) -> Result<Resolution> {
        let mut resolution = Resolution::default();
        params.read("grid", &["res"], |_, v| {
            resolution = v.parse()?;
            Ok(())
        })?;
        Ok(resolution)
    }
}

impl AccelStructure for Grid {
    /// One key: `res`, the cell counts (`Resolution`'s forms: auto, auto:LAMBDA, N, AxBxC).
    fn build(tris: &[TriAccel], params: &AccelParams) -> Result<Grid> {
        Grid::build(tris, Grid::resolution_from(params)?)
    }

    fn params(&self) -> AccelParams {
        AccelParams::from(self.resolution)
    }

    /// Rebuilt as it was built, serving the same traversal (`stepping`).
    fn update(&mut self, tris: &[TriAccel]) -> Result<&'static str> {
        *self = Grid {
            stepping: self.stepping,
            ..Grid::build(tris, self.resolution)?
        };
        Ok("rebuilt")
    }

    fn bounds(&self, _tris: &[TriAccel]) -> Aabb {
        self.bounds
    }

    fn memory(&self) -> Vec<(&'static str, usize)> {
        vec![
            ("cells", std::mem::size_of_val(self.cells.as_slice())),
            ("refs", std::mem::size_of_val(self.refs.as_slice())),
        ]
    }

    fn summary(&self) -> String {
        let s = &self.stats;
        format!(
            "grid {}, {:.2} refs/tri (built in {:.1} ms)",
            dims_str(s.dims),
            s.refs_per_triangle(),
            s.build_ms
        )
    }

    fn info_lines(&self, _tris: &[TriAccel]) -> Result<Vec<(String, String)>> {
        let s = &self.stats;
        Ok(vec![
            ("grid".into(), format!("{} = {} cells", dims_str(s.dims), s.cells)),
            ("empty cells".into(), format!("{:.1}%", s.empty_fraction() * 100.0)),
            (
                "references".into(),
                format!(
                    "{} ({:.2} per triangle, max {} in a cell)",
                    s.references,
                    s.refs_per_triangle(),
                    s.max_refs_in_cell
                ),
            ),
            ("build".into(), format!("{:.2} ms", s.build_ms)),
        ])
    }
}

/// The grid's walks (`dda.rs`, `packet.rs`), by its `stepping`: cell by cell or by jumps.
impl Walks for Grid {
    #[inline]
    fn intersect<C: Counters>(&self, tris: &[TriAccel], ray: &Ray, counters: &mut C) -> Hit {
        Grid::intersect(self, tris, ray, self.stepping, counters)
    }

    #[inline]
    fn occluded<C: Counters>(&self, tris: &[TriAccel], ray: &Ray, counters: &mut C) -> bool {
        Grid::occluded(self, tris, ray, self.stepping, counters)
    }

    #[inline]
    fn intersect_packet<C: Counters>(&self, tris: &[TriAccel], rays: &[Ray], counters: &mut [C]) -> [Hit; PACKET] {
        Grid::intersect_packet(self, tris, rays, self.stepping, counters)
    }

    #[inline]
    fn occluded_packet<C: Counters>(&self, tris: &[TriAccel], rays: &[Ray], counters: &mut [C]) -> [bool; PACKET] {
        Grid::occluded_packet(self, tris, rays, self.stepping, counters)
    }

    /// Every cell the ray crosses (no early exit), each triangle tested where it is met;
    /// a triangle in several cells is kept once (`dedup_hits`). The grid finds every hit
    /// brute force finds (enlarged cell boxes), so this is brute force's set.
    fn all_hits(&self, tris: &[TriAccel], ray: &Ray, out: &mut Vec<Hit>) {
        let from = out.len();
        self.walk(ray, self.stepping, &mut NoCounters, |refs, _, _| {
            for &r in refs {
                if let Some(h) = tris[r as usize].intersect(ray.origin, ray.dir, ray.t_min, ray.t_max) {
                    out.push(h.on(r));
                }
            }
            std::ops::ControlFlow::Continue(())
        });
        dedup_hits(out, from);
    }

    /// Branch and bound over the structure's own cells or nodes (`closest.rs`).
    fn closest_point(&self, tris: &[TriAccel], p: glam::Vec3) -> crate::accel::closest::ClosestPoint {
        Grid::closest_point(self, tris, p)
    }
}
