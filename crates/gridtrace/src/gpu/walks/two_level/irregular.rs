//! The irregular grid under a top level: each mesh's grid as the CPU built it in the mesh's own
//! space, laid one after another in the walk's shared arrays (`irregular_rows.wgsl`), its
//! lattice of virtual voxels a row of a table that the mesh's header names, as the uniform
//! grid's is (`GRID`).

use super::{Laid, LatticeRow, TOP_LEVEL, TOP_LEVEL_ARRAY, WGSL_CONSTANTS};
use crate::accel::StructureId;
use crate::accel::{Accel, IrrCell, Structure};
use crate::gpu::layout::GpuTri;
use crate::gpu::walks::{POINT_RING, WalkSpec, irregular};
use crate::{Error, Result};

/// The meshes' irregular grids under the top level: their entries, voxel maps and references
/// in one array of words, their cells one mesh after another, their lattices in a table, their
/// triangles in the shared `tris`.
pub const IRREGULAR: WalkSpec = WalkSpec {
    structure: StructureId::Irregular,
    name: "irregular (two levels)",
    wgsl: &[
        irregular::WALK,
        include_str!("irregular_rows.wgsl"),
        POINT_RING,
        TOP_LEVEL,
    ],
    prefix: "top",
    arrays: &[
        ("irr_words", "irr_words"),
        ("irr_cells", "irr_cells"),
        ("lattices", "irr_lattices"),
        TOP_LEVEL_ARRAY,
    ],
    device_build: false,
    tlas: None,
    software_max_tris: None,
    constants: WGSL_CONSTANTS,
    bottom: Some("irr"),
};

/// The bottom walk's arrays for meshes of irregular grids (`IRREGULAR.arrays` but the top
/// level's), the shared triangles (every mesh's), and each mesh's header (its row of the
/// lattice table).
///
/// A mesh's words are its entries (kept: a top cell's `begin` counts from its own voxel maps,
/// which its row's `first_map` names), then its voxel maps (each cell moved by the cells before
/// the mesh's), then its references (each triangle moved by the triangles before it); its cells'
/// starts moved to where its references lie among the words. Its cells keep their sentinel, so
/// a cell's references end where the next cell's start, the mesh's last cell's included.
pub(super) fn layout(meshes: &[&Accel]) -> Result<Laid> {
    let too_many = || {
        Error::InvalidInput("the scene's irregular grids have more than 2^32 words, cells or triangles together".into())
    };
    let at = |n: usize| u32::try_from(n).map_err(|_| too_many());
    let (mut words, mut cells, mut rows, mut tris): (Vec<u32>, Vec<IrrCell>, Vec<LatticeRow>, Vec<GpuTri>) =
        Default::default();
    let mut headers = Vec::with_capacity(meshes.len());
    for (k, m) in meshes.iter().enumerate() {
        let Structure::Irregular(g) = &m.structure else {
            unreachable!("walk_for named the irregular grid's walk for every mesh");
        };
        let first_entry = at(words.len())?;
        let first_map = at(words.len() + g.entries.len())?;
        let first_ref = at(words.len() + g.entries.len() + g.voxel_map.len())?;
        let first_cell = at(cells.len())?;
        let first_tri = at(tris.len())?;
        // Every moved number below fits (the counts after this mesh do).
        at(words.len() + g.entries.len() + g.voxel_map.len() + g.refs.len())?;
        at(cells.len() + g.cells.len())?;
        at(tris.len() + m.tris.len())?;
        rows.push(LatticeRow {
            lo: g.bounds.min.to_array(),
            first_cell: first_entry,
            hi: g.bounds.max.to_array(),
            first_tri,
            cell: g.voxel_size.to_array(),
            shift: g.shift,
            // The CPU walk's own reciprocal, bit for bit (as `irregular::upload`).
            inv_cell: g.inv_voxel_size.to_array(),
            first_map,
            dims: g.voxel_dims().to_array(),
            _pad1: 0,
        });
        headers.push([k as u32, 0]);
        words.extend_from_slice(&g.entries);
        words.extend(g.voxel_map.iter().map(|&c| c + first_cell));
        words.extend(g.refs.iter().map(|&t| t + first_tri));
        cells.extend(g.cells.iter().map(|c| IrrCell {
            start: c.start + first_ref,
            ..*c
        }));
        tris.extend(GpuTri::all(&m.tris));
    }
    let arrays = vec![
        bytemuck::cast_slice(&words).to_vec(),
        bytemuck::cast_slice(&cells).to_vec(),
        bytemuck::cast_slice(&rows).to_vec(),
    ];
    Ok(Laid { arrays, tris, headers })
}
