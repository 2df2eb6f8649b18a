//! Mitsuba's named materials reduced to chiaro's numbers: conductors'
//! complex IOR at RGB (the RGB reductions of Mitsuba's tabulated `eta` and
//! `k`, as its RGB variants use them) and dielectrics' named IORs.

use chiaro_core::Vec3;

/// `(name, eta, k)` per RGB channel of Mitsuba's conductor `material`
/// names (`none` is the ideal mirror, Mitsuba's default).
const CONDUCTORS: &[(&str, [f32; 3], [f32; 3])] = &[
    (
        "Ag",
        [0.1552646, 0.1167233, 0.1383807],
        [4.828343, 3.122246, 2.14695],
    ),
    (
        "Al",
        [1.65746, 0.880369, 0.521229],
        [9.223869, 6.269523, 4.837001],
    ),
    (
        "Au",
        [0.143119, 0.374957, 1.442479],
        [3.98316, 2.385721, 1.603215],
    ),
    (
        "Cr",
        [4.369683, 2.916702, 1.654701],
        [5.206434, 4.231365, 3.754947],
    ),
    (
        "Cu",
        [0.200438, 0.924033, 1.102212],
        [3.912949, 2.452848, 2.142188],
    ),
    (
        "Hg",
        [2.398931, 1.440025, 0.909551],
        [6.327627, 4.371941, 3.42179],
    ),
    (
        "Ir",
        [3.08641, 2.082194, 1.617887],
        [5.592151, 4.067176, 3.267261],
    ),
    (
        "Li",
        [0.265787, 0.19561, 0.22092],
        [3.540174, 2.311131, 1.668593],
    ),
    (
        "Mo",
        [4.483701, 3.525458, 2.776077],
        [4.111131, 3.420872, 3.150603],
    ),
    (
        "Na",
        [0.060267, 0.056141, 0.061991],
        [3.179291, 2.11248, 1.579094],
    ),
    (
        "Ni",
        [2.367275, 1.663358, 1.467055],
        [4.498833, 3.050164, 2.345427],
    ),
    (
        "Rh",
        [2.585795, 1.860187, 1.554428],
        [6.782293, 4.70295, 3.976089],
    ),
    (
        "Ta",
        [2.062585, 2.393092, 2.628068],
        [2.408047, 1.741371, 1.947038],
    ),
    (
        "TiN",
        [1.648469, 1.150448, 1.37978],
        [3.36846, 1.943489, 1.102012],
    ),
    (
        "V",
        [4.277513, 3.513154, 2.761126],
        [3.491184, 2.889358, 3.111697],
    ),
    (
        "W",
        [4.370703, 3.300297, 2.998267],
        [3.500678, 2.604865, 2.273193],
    ),
    ("none", [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]),
];

/// Mitsuba's named IORs (its `ior.h` table).
const IORS: &[(&str, f32)] = &[
    ("vacuum", 1.0),
    ("helium", 1.000_036),
    ("hydrogen", 1.000_132),
    ("air", 1.000_277),
    ("carbon dioxide", 1.000_45),
    ("water", 1.333),
    ("acetone", 1.36),
    ("ethanol", 1.361),
    ("carbon tetrachloride", 1.461),
    ("glycerol", 1.4729),
    ("benzene", 1.501),
    ("silicone oil", 1.520_45),
    ("bromine", 1.661),
    ("water ice", 1.31),
    ("fused quartz", 1.458),
    ("pyrex", 1.47),
    ("acrylic glass", 1.49),
    ("polypropylene", 1.49),
    ("bk7", 1.5046),
    ("sodium chloride", 1.544),
    ("amber", 1.55),
    ("pet", 1.575),
    ("diamond", 2.419),
];

/// The RGB `(eta, k)` of a named conductor, or `None` for an unknown name.
pub fn conductor(name: &str) -> Option<(Vec3, Vec3)> {
    CONDUCTORS
        .iter()
        .find(|(n, _, _)| *n == name)
        .map(|(_, eta, k)| (Vec3::from_array(*eta), Vec3::from_array(*k)))
}

/// The names [`conductor`] knows, for messages.
pub fn conductor_names() -> Vec<&'static str> {
    CONDUCTORS.iter().map(|(n, _, _)| *n).collect()
}

/// The IOR of a named medium, or `None`.
pub fn ior(name: &str) -> Option<f32> {
    let name = name.to_ascii_lowercase();
    IORS.iter().find(|(n, _)| *n == name).map(|(_, v)| *v)
}

/// Reflectance at normal incidence of a dielectric interface of relative
/// IOR `eta`: `((eta - 1) / (eta + 1))^2`.
pub fn dielectric_f0(eta: f32) -> f32 {
    let r = (eta - 1.0) / (eta + 1.0);
    r * r
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_incidence_closed_forms() {
        use chiaro_core::shading::fresnel_conductor;
        assert!((dielectric_f0(1.5) - 0.04).abs() < 1e-7);
        // The ideal mirror reflects everything.
        let (eta, k) = conductor("none").expect("test input");
        assert_eq!(fresnel_conductor(1.0, eta, k), Vec3::ONE);
        // Gold is yellow: red reflects more than blue, all within (0, 1).
        let (eta, k) = conductor("Au").expect("test input");
        let f = fresnel_conductor(1.0, eta, k);
        assert!(f.x > f.z && f.x < 1.0 && f.z > 0.0, "{f}");
        assert_eq!(ior("BK7"), Some(1.5046));
        assert!(conductor("Unobtainium").is_none());
    }
}
