//! Mitsuba's named materials reduced to chiaro's numbers: conductors'
//! complex IOR at RGB (the RGB reductions of Mitsuba's tabulated `eta` and
//! `k`, as its RGB variants use them) and dielectrics' named IORs.

use chiaro_core::Vec3;

/// `(name, eta, k)` per RGB channel of Mitsuba's conductor `material`
/// names (`none` is the ideal mirror, Mitsuba's default).
const CONDUCTORS: &[(&str, [f32; 3], [f32; 3])] = &[
    (
        "Ag",
        [0.155_264_6, 0.116_723_3, 0.138_380_7],
        [4.828_343, 3.122_246, 2.146_950],
    ),
    (
        "Al",
        [1.657_460, 0.880_369, 0.521_229],
        [9.223_869, 6.269_523, 4.837_001],
    ),
    (
        "Au",
        [0.143_119, 0.374_957, 1.442_479],
        [3.983_160, 2.385_721, 1.603_215],
    ),
    (
        "Cr",
        [4.369_683, 2.916_702, 1.654_701],
        [5.206_434, 4.231_365, 3.754_947],
    ),
    (
        "Cu",
        [0.200_438, 0.924_033, 1.102_212],
        [3.912_949, 2.452_848, 2.142_188],
    ),
    (
        "Hg",
        [2.398_931, 1.440_025, 0.909_551],
        [6.327_627, 4.371_941, 3.421_790],
    ),
    (
        "Ir",
        [3.086_410, 2.082_194, 1.617_887],
        [5.592_151, 4.067_176, 3.267_261],
    ),
    (
        "Li",
        [0.265_787, 0.195_610, 0.220_920],
        [3.540_174, 2.311_131, 1.668_593],
    ),
    (
        "Mo",
        [4.483_701, 3.525_458, 2.776_077],
        [4.111_131, 3.420_872, 3.150_603],
    ),
    (
        "Na",
        [0.060_267, 0.056_141, 0.061_991],
        [3.179_291, 2.112_480, 1.579_094],
    ),
    (
        "Ni",
        [2.367_275, 1.663_358, 1.467_055],
        [4.498_833, 3.050_164, 2.345_427],
    ),
    (
        "Rh",
        [2.585_795, 1.860_187, 1.554_428],
        [6.782_293, 4.702_950, 3.976_089],
    ),
    (
        "Ta",
        [2.062_585, 2.393_092, 2.628_068],
        [2.408_047, 1.741_371, 1.947_038],
    ),
    (
        "TiN",
        [1.648_469, 1.150_448, 1.379_780],
        [3.368_460, 1.943_489, 1.102_012],
    ),
    (
        "V",
        [4.277_513, 3.513_154, 2.761_126],
        [3.491_184, 2.889_358, 3.111_697],
    ),
    (
        "W",
        [4.370_703, 3.300_297, 2.998_267],
        [3.500_678, 2.604_865, 2.273_193],
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

/// Reflectance at normal incidence of a conductor of complex IOR
/// `eta + i k` (relative to the outside medium), per channel:
/// `((eta - 1)^2 + k^2) / ((eta + 1)^2 + k^2)` (Born and Wolf, section 14.2).
pub fn conductor_f0(eta: Vec3, k: Vec3) -> Vec3 {
    let k2 = k * k;
    let num = (eta - Vec3::ONE) * (eta - Vec3::ONE) + k2;
    let den = (eta + Vec3::ONE) * (eta + Vec3::ONE) + k2;
    (num / den.max(Vec3::splat(1e-12))).clamp(Vec3::ZERO, Vec3::ONE)
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
        // A dielectric is a conductor with k = 0.
        let f = conductor_f0(Vec3::splat(1.5), Vec3::ZERO);
        assert!((f.x - dielectric_f0(1.5)).abs() < 1e-7);
        assert!((dielectric_f0(1.5) - 0.04).abs() < 1e-7);
        // The ideal mirror reflects everything.
        let (eta, k) = conductor("none").unwrap();
        assert_eq!(conductor_f0(eta, k), Vec3::ONE);
        // Gold is yellow: red reflects more than blue, all within (0, 1).
        let (eta, k) = conductor("Au").unwrap();
        let f = conductor_f0(eta, k);
        assert!(f.x > f.z && f.x < 1.0 && f.z > 0.0, "{f}");
        assert_eq!(ior("BK7"), Some(1.5046));
        assert!(conductor("Unobtainium").is_none());
    }
}
