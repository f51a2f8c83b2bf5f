//! The variants table's tests: parsing, printing, defaults, the suite's order, the overrides.

use super::*;
use crate::accel::StructureId;

/// Every value of every key parses and prints back to the same text; partial strings keep
/// the other keys default; bad keys and values are errors that name them and the valid set.
#[test]
fn parse_and_print() {
    let d = GpuVariants::default();
    assert_eq!("".parse::<GpuVariants>().unwrap(), d);
    assert_eq!("default".parse::<GpuVariants>().unwrap(), d);
    assert_eq!(
        d.to_string(),
        "bvh=binary,stack=short,order=tiles,appends=workgroup,stats=off,checks=on"
    );
    assert_eq!(d.changes(), "default");
    let v: GpuVariants = "bvh=wide8, stack=short3,order=tiles,appends=workgroup,stats=off,checks=off"
        .parse()
        .unwrap();
    assert_eq!(
        v,
        GpuVariants {
            bvh: BvhLayout::Wide8,
            stack: BvhStack::Short(3),
            order: RayOrder::Tiles,
            appends: Appends::Workgroup,
            stats: false,
            checks: false,
        }
    );
    assert_eq!(v.to_string().parse::<GpuVariants>().unwrap(), v);
    let text = "bvh=wide8,stack=short,order=tiles,appends=workgroup,stats=off,checks=off";
    assert_eq!(text.parse::<GpuVariants>().unwrap().to_string(), text);
    let one: GpuVariants = "stack=private".parse().unwrap();
    assert_eq!(one.stack, BvhStack::Private);
    assert_eq!(one.changes(), "stack=private");
    assert_eq!("stack=short".parse::<GpuVariants>().unwrap().changes(), "default");
    assert_eq!(
        GpuVariants::before_hardware().changes(),
        "stack=private,order=rows,appends=per_ray,stats=on"
    );
    for (bad, names) in [
        ("bvh=wide4", ["bvh=wide4", "binary|wide8"]),
        ("colour=red", ["'colour'", "appends=workgroup|per_ray"]),
        ("stack=short17", ["short17", "shortN"]),
        ("stack=short0", ["short0", "shortN"]),
        ("stats", ["'stats'", "KEY=VALUE"]),
        ("checks=maybe", ["checks=maybe", "on|off"]),
    ] {
        let e = bad.parse::<GpuVariants>().unwrap_err();
        for n in names {
            assert!(e.contains(n), "{bad}: {e}");
        }
    }
}

/// The suite is the default, one change of each key (both other appends), each exactly one
/// key off, and the kernels as first written, in this order (the hardware reports' rows).
#[test]
fn suite_is_default_plus_single_changes() {
    let s = GpuVariants::suite();
    assert_eq!(s[0], GpuVariants::default());
    assert_eq!(s.len(), 1 + VARIANTS.len() + 1 + 1);
    assert_eq!(s.last(), Some(&GpuVariants::before_hardware()));
    for v in &s[1..s.len() - 1] {
        assert_eq!(v.changes().split(',').count(), 1, "{v}");
        assert_ne!(v.changes(), "default");
    }
    let mut labels: Vec<String> = s.iter().map(|v| v.changes()).collect();
    assert_eq!(
        labels,
        [
            "default",
            "bvh=wide8",
            "stack=private",
            "order=rows",
            "appends=per_ray",
            "appends=subgroup",
            "stats=on",
            "checks=off",
            "stack=private,order=rows,appends=per_ray,stats=on",
        ]
    );
    labels.dedup();
    assert_eq!(labels.len(), s.len());
    assert!(!s[1].applies_to(StructureId::Grid) && s[1].applies_to(StructureId::Bvh));
    assert!(!s[2].applies_to(StructureId::Irregular) && s[2].applies_to(StructureId::Bvh));
    assert!(s[3].applies_to(StructureId::Grid));
}

/// The table's rows set every field: the default and the kernels as first written are the
/// same whatever value they start from, and the overrides are those common.wgsl declares.
#[test]
fn the_table_sets_every_field() {
    let other = GpuVariants {
        bvh: BvhLayout::Wide8,
        stack: BvhStack::Short(3),
        order: RayOrder::Tiles,
        appends: Appends::Subgroup,
        stats: true,
        checks: true,
    };
    for value_of in [
        (|r: &VariantSpec| r.default_value()) as fn(&VariantSpec) -> &'static str,
        |r| r.first_written,
    ] {
        assert_eq!(
            GpuVariants::from_table_over(other, value_of),
            GpuVariants::from_table(value_of)
        );
    }
    assert_eq!(
        GpuVariants::default(),
        GpuVariants {
            bvh: BvhLayout::Binary,
            stack: BvhStack::Short(SHORT_STACK_DEFAULT),
            order: RayOrder::Tiles,
            appends: Appends::Workgroup,
            stats: false,
            checks: true,
        }
    );
    assert_eq!(
        GpuVariants::before_hardware(),
        GpuVariants {
            bvh: BvhLayout::Binary,
            stack: BvhStack::Private,
            order: RayOrder::Rows,
            appends: Appends::PerRay,
            stats: true,
            checks: true,
        }
    );
    let mut names: Vec<&str> = GpuVariants::default().overrides().iter().map(|o| o.0).collect();
    names.sort();
    assert_eq!(names, ["RAY_STATS", "SHORT_STACK", "TILE_ORDER", "WG_APPENDS"]);
    let common = include_str!("../shaders/common.wgsl");
    for n in names {
        assert!(common.contains(&format!("override {n}:")), "common.wgsl lacks {n}");
    }
    let over = |s: &str| s.parse::<GpuVariants>().unwrap().overrides();
    assert!(over("stack=short3").contains(&("SHORT_STACK", 3.0)));
    assert!(over("stack=private").contains(&("SHORT_STACK", SHORT_STACK_DEFAULT as f64)));
    assert!(over("order=rows").contains(&("TILE_ORDER", 0.0)));
    assert!(over("appends=subgroup").contains(&("WG_APPENDS", 0.0)));
    assert!(over("stats=on").contains(&("RAY_STATS", 1.0)));
}

/// The keys as errors and help list them: each key's values, the default first.
#[test]
fn keys_text_lists_every_value() {
    assert_eq!(
        keys_text(),
        "bvh=binary|wide8, stack=short|private|shortN (N = 1..16), order=tiles|rows, \
         appends=workgroup|per_ray|subgroup, stats=off|on, checks=on|off"
    );
    let printed = GpuVariants {
        stack: BvhStack::Short(40),
        ..GpuVariants::default()
    };
    assert_eq!(printed.changes(), "stack=short40");
}
