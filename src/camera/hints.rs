//! Camera sampling hints for a new area: the `[sampling]` part of the scene file `insgen init` writes.

use std::fmt::Write as _;

use super::SamplingConfig;

/// The `[sampling]` text for an area of `size` metres (west–east, south–north): the defaults spelled
/// out as comments, with the number of cam2 lattice nodes they give, and, on an area too small for
/// 3 × 3 nodes of the default lattice, a closer `[sampling.grid] spacing_m` (about 3 × 3 nodes, whole
/// 10 m).
pub fn sampling_hints(size: [f64; 2]) -> String {
    let mut t = String::new();
    let d = SamplingConfig::default();
    let g = &d.grid;
    let nodes =
        |spacing_m: f64| size.iter().map(|s| ((s / spacing_m).floor() as usize).max(1)).product::<usize>();
    let default_nodes = nodes(g.spacing_m);
    let _ = writeln!(
        &mut t,
        "\n# Camera sampling (`insgen sample`; every key and default: src/camera/config.rs). With the\n\
         # defaults, cam2 (grid) flies {}–{} m above the ground on a {} m lattice: {} node(s) here, {} view\n\
         # angles each; cam3 (regular) on lines {} m apart; cam1 (irregular) in sequences of {} frames.",
        g.height_range_m[0],
        g.height_range_m[1],
        g.spacing_m,
        default_nodes,
        g.pitch_deg.len(),
        d.regular.line_spacing_m,
        d.irregular.frames_per_sequence
    );
    let _ = writeln!(
        &mut t,
        "[sampling]\n# min_visible_buildings = {}  # buildings a view must show",
        d.min_visible_buildings
    );
    let _ = writeln!(
        &mut t,
        "# max_off_map_share = {}  # share of a view allowed beyond the model",
        d.max_off_map_share
    );
    if default_nodes < 9 {
        // A small area: a lattice of about 3 × 3 nodes, in whole 10 m.
        let spacing_m = ((size[0].min(size[1]) / 3.0 / 10.0).floor() * 10.0).max(10.0);
        let _ = writeln!(
            &mut t,
            "\n# The area is small for the {} m lattice: {} m gives {} node(s).\n[sampling.grid]\nspacing_m = {spacing_m:.1}",
            g.spacing_m,
            spacing_m,
            nodes(spacing_m)
        );
    } else {
        let _ = writeln!(&mut t, "# [sampling.grid]\n# spacing_m = {:.1}", g.spacing_m);
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The hints parse as the scene file's `[sampling]` table.
    fn parsed(text: &str) -> SamplingConfig {
        SamplingConfig::from_scene_toml(text, Some(std::path::Path::new("x.toml"))).unwrap()
    }

    #[test]
    fn a_city_keeps_the_defaults() {
        let t = sampling_hints([2000.0, 1500.0]);
        assert!(t.contains("a 100 m lattice: 300 node(s) here"), "{t}");
        assert_eq!(parsed(&t), SamplingConfig::default());
    }

    #[test]
    fn a_small_area_gets_a_closer_lattice() {
        let t = sampling_hints([250.0, 180.0]);
        let cfg = parsed(&t);
        // min(250, 180) / 3 = 60 m → 4 × 3 nodes.
        assert_eq!(cfg.grid.spacing_m, 60.0);
        assert!(t.contains("60 m gives 12 node(s)"), "{t}");
        assert_eq!(cfg.grid.height_range_m, SamplingConfig::default().grid.height_range_m);
    }
}
