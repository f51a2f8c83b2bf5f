//! The top level's build and walks against scans of the boxes.

use super::*;

/// Every box the ray enters is visited, once, whatever the tree's shape (against a scan);
/// what else is visited shares a leaf whose box the ray enters. `entered` finds the
/// same.
#[test]
fn walk_visits_every_box_a_scan_finds_once() {
    let mut s = 7u64;
    let mut r = || {
        s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((s >> 33) as f32 / (1u64 << 31) as f32) * 2.0 - 1.0
    };
    for n in [0usize, 1, 2, 3, 5, 17, 300] {
        let boxes: Vec<Aabb> = (0..n)
            .map(|_| {
                let c = Vec3::new(r(), r(), r()) * 10.0;
                let h = Vec3::new(r().abs(), r().abs(), r().abs()) + 0.1;
                Aabb { min: c - h, max: c + h }
            })
            .collect();
        let t = TopLevel::build(&boxes);
        // Each ray, and what it entered alone, for the batch below.
        let mut batch = Vec::new();
        for _ in 0..200 {
            let o = Vec3::new(r(), r(), r()) * 15.0;
            let d = Vec3::new(r(), r(), r());
            let mut seen = Vec::new();
            t.walk(&Ray::new(o, d), |i, _, t_max| {
                seen.push(i);
                t_max
            });
            seen.sort_unstable();
            // The unordered walk enters the same boxes (each slot's box tested alike).
            let mut entered = Vec::new();
            t.entered([(7, o, d)].into_iter(), 0.0, f32::INFINITY, &mut entered);
            assert!(entered.iter().all(|e| e.2 == 7));
            let mut entered: Vec<u32> = entered.iter().map(|e| e.1).collect();
            entered.sort_unstable();
            assert_eq!(entered, seen, "n = {n}: the unordered walk differs");
            let inv = d.recip();
            let want: Vec<u32> = (0..n as u32)
                .filter(|&i| boxes[i as usize].clip(o, inv, 0.0, f32::INFINITY).is_some())
                .collect();
            assert!(seen.windows(2).all(|w| w[0] < w[1]), "n = {n}: visited twice");
            assert!(
                want.iter().all(|i| seen.contains(i)),
                "n = {n}: {want:?} not in {seen:?}"
            );
            batch.push((batch.len() as u32, o, d, seen));
        }
        // All the rays at once, their walks interleaved: each ray's entries as alone, and
        // with the same entry distances.
        let mut found = Vec::new();
        t.entered(batch.iter().map(|b| (b.0, b.1, b.2)), 0.0, f32::INFINITY, &mut found);
        for (k, _, _, seen) in &batch {
            let mut mine: Vec<u32> = found.iter().filter(|e| e.2 == *k).map(|e| e.1).collect();
            mine.sort_unstable();
            assert_eq!(&mine, seen, "n = {n}, ray {k}: the interleaved walks differ");
        }
    }
}

/// The nodes are not left nearly empty: at most one node for four boxes.
#[test]
fn nodes_are_nearly_full() {
    let mut r = crate::util::Rng::new(3);
    for n in [1usize, 7, 9, 100, 1000, 4097] {
        let boxes: Vec<Aabb> = (0..n)
            .map(|_| {
                let c = Vec3::new(r.next_f32(), r.next_f32(), r.next_f32()) * 20.0;
                Aabb {
                    min: c - 0.5,
                    max: c + 0.5,
                }
            })
            .collect();
        let t = TopLevel::build(&boxes);
        let slots: u32 = t.nodes.iter().map(|n| n.valid.count_ones()).sum();
        assert_eq!(
            slots as usize,
            n + t.nodes.len() - 1,
            "n = {n}: every item and node once"
        );
        assert!(t.nodes.len() <= n / 4 + 1, "n = {n}: {} nodes", t.nodes.len());
        let mut seen = t.boxes();
        seen.sort_by(|a, b| a.min.x.total_cmp(&b.min.x));
        let mut want = boxes.clone();
        want.sort_by(|a, b| a.min.x.total_cmp(&b.min.x));
        assert_eq!(seen, want, "n = {n}: each box in a leaf slot as given");
    }
}
