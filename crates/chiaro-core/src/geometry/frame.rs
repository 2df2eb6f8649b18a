//! Orthonormal frames.

use glam::Vec3;

/// An orthonormal basis with `n` as its z axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    /// Local x.
    pub s: Vec3,
    /// Local y.
    pub t: Vec3,
    /// Local z (the normal).
    pub n: Vec3,
}

impl Frame {
    /// A frame around the unit vector `n` (Duff et al. 2017, "Building an
    /// Orthonormal Basis, Revisited").
    pub fn from_normal(n: Vec3) -> Self {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        let s = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
        let t = Vec3::new(b, sign + n.y * n.y * a, -n.y);
        Self { s, t, n }
    }

    /// Local to world.
    #[inline]
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.s * v.x + self.t * v.y + self.n * v.z
    }

    /// World to local.
    #[inline]
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.s), v.dot(self.t), v.dot(self.n))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_are_orthonormal() {
        for n in [
            Vec3::Z,
            -Vec3::Z,
            Vec3::X,
            Vec3::new(0.3, -0.5, 0.8).normalize(),
        ] {
            let f = Frame::from_normal(n);
            assert!(f.s.dot(f.t).abs() < 1e-6 && f.s.dot(f.n).abs() < 1e-6);
            assert!((f.s.length() - 1.0).abs() < 1e-6 && (f.t.length() - 1.0).abs() < 1e-6);
            assert!((f.s.cross(f.t) - f.n).length() < 1e-5);
            let v = Vec3::new(0.1, 0.2, 0.3);
            assert!((f.to_local(f.to_world(v)) - v).length() < 1e-6);
        }
    }
}
