//! Small closed meshes the tests place: Open3D's unit cube and axis-aligned boxes.

use glam::Vec3;

/// The unit cube as Open3D's `create_box` makes it: vertex `4x + 2y + z` at `(x, y, z)`, each
/// side two faces split along a diagonal, normals outward (winding number 1 inside). Open3D's
/// own count test casts through its diagonals.
pub fn open3d_cube() -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let v = (0..8u32)
        .map(|i| [(i >> 2) as f32, ((i >> 1) & 1) as f32, (i & 1) as f32])
        .collect();
    let f = vec![
        [0, 1, 3],
        [0, 3, 2],
        [4, 6, 7],
        [4, 7, 5],
        [0, 4, 5],
        [0, 5, 1],
        [2, 3, 7],
        [2, 7, 6],
        [0, 2, 6],
        [0, 6, 4],
        [1, 5, 7],
        [1, 7, 3],
    ];
    (v, f)
}

/// An axis-aligned box from `lo` to `hi` as 8 vertices and 12 triangles (two a face, each
/// face's pair sharing its diagonal): the rooms and boxes of the sensor tests.
pub fn cuboid(lo: Vec3, hi: Vec3) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let v = (0..8)
        .map(|i| {
            [
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            ]
        })
        .collect();
    let quads = [
        [0, 1, 3, 2],
        [4, 6, 7, 5],
        [0, 4, 5, 1],
        [2, 3, 7, 6],
        [0, 2, 6, 4],
        [1, 5, 7, 3],
    ];
    let f = quads
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect();
    (v, f)
}
