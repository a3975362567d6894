//! Boxes against the camera: inside the frustum (all planes, or only those
//! a parent box straddled), and distances from the eye.

use glam::DVec3;

/// Is the box `[min, max]` at least partly inside the frustum `planes`
/// (inward normals)? Conservative: a box near a corner may pass.
#[inline]
pub fn box_in_frustum(planes: &[[f64; 4]; 6], min: [f32; 3], max: [f32; 3]) -> bool {
    frustum_mask(planes, ALL_PLANES, min, max).is_some()
}

/// Every frustum plane, as a mask for [`frustum_mask`].
pub const ALL_PLANES: u8 = 0b11_1111;

/// Test the box against the planes in `mask` (bit i: plane i): `None` when
/// it lies wholly outside one of them, else the planes it straddles. A box
/// inside a plane has children inside it, so a walk down a tree passes
/// the mask on and tests fewer planes as it goes.
#[inline]
pub fn frustum_mask(planes: &[[f64; 4]; 6], mask: u8, min: [f32; 3], max: [f32; 3]) -> Option<u8> {
    let mut straddled = 0;
    for (i, p) in planes.iter().enumerate() {
        if mask & (1 << i) == 0 {
            continue;
        }
        // The box corners furthest along and against the plane normal.
        let (mut far, mut near) = (p[3], p[3]);
        for k in 0..3 {
            let (hi, lo) = if p[k] >= 0.0 {
                (max[k], min[k])
            } else {
                (min[k], max[k])
            };
            far += p[k] * hi as f64;
            near += p[k] * lo as f64;
        }
        if far < 0.0 {
            return None;
        }
        if near < 0.0 {
            straddled |= 1 << i;
        }
    }
    Some(straddled)
}

/// Distance from `eye` to the nearest point of the box, metres (0 inside).
#[inline]
pub fn box_distance(eye: DVec3, min: [f32; 3], max: [f32; 3]) -> f64 {
    box_distance_squared(eye, min, max).sqrt()
}

/// [`box_distance`] squared.
#[inline]
pub fn box_distance_squared(eye: DVec3, min: [f32; 3], max: [f32; 3]) -> f64 {
    let gap = |k: usize, e: f64| (min[k] as f64 - e).max(e - max[k] as f64).max(0.0);
    let (x, y, z) = (gap(0, eye.x), gap(1, eye.y), gap(2, eye.z));
    x * x + y * y + z * z
}

/// Distance from `eye` to the furthest point of the box, squared.
#[inline]
pub(super) fn box_farthest_distance_squared(eye: DVec3, min: [f32; 3], max: [f32; 3]) -> f64 {
    let reach = |k: usize, e: f64| (e - min[k] as f64).abs().max((max[k] as f64 - e).abs());
    let (x, y, z) = (reach(0, eye.x), reach(1, eye.y), reach(2, eye.z));
    x * x + y * y + z * z
}
