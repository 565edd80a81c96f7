//! 2-D convex hull by gift wrapping (Jarvis march), used on the skeleton key points
//! projected on their coronal plane (first two principal axes).
//!
//! Output: hull vertex indices counter-clockwise, starting at the lowest-leftmost point.
//! Points lying on a hull edge between two vertices are not vertices (as in qhull), and
//! duplicates count once. Runs in `O(n h)` for `h` hull vertices; no allocation.

use crate::error::{Error, Result};
use nalgebra::Vector2;

/// 2-D point.
pub type Vec2 = Vector2<f32>;

fn cross(o: &Vec2, a: &Vec2, b: &Vec2) -> f32 {
    (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x)
}

/// Convex hull of `points` into `out` (indices, counter-clockwise). A single distinct
/// point gives one vertex, collinear points give the two extremes.
pub fn gift_wrap<const H: usize>(points: &[Vec2], out: &mut heapless::Vec<u16, H>) -> Result<()> {
    out.clear();
    if points.len() > usize::from(u16::MAX) {
        return Err(Error::Capacity {
            capacity: u32::from(u16::MAX),
        });
    }
    let Some(start) = (0..points.len()).min_by(|&a, &b| {
        let (p, q) = (points[a], points[b]);
        p.y.total_cmp(&q.y).then(p.x.total_cmp(&q.x))
    }) else {
        return Ok(());
    };
    let mut p = start;
    // A hull has at most n vertices: the bound only guards against rounding loops.
    for _ in 0..=points.len() {
        out.push(p as u16)
            .map_err(|_| Error::Capacity { capacity: H as u32 })?;
        let mut q = usize::MAX;
        for r in 0..points.len() {
            if points[r] == points[p] {
                continue;
            }
            if q == usize::MAX {
                q = r;
                continue;
            }
            let c = cross(&points[p], &points[q], &points[r]);
            let farther =
                (points[r] - points[p]).norm_squared() > (points[q] - points[p]).norm_squared();
            if c < 0.0 || (c == 0.0 && farther) {
                q = r;
            }
        }
        if q == usize::MAX || points[q] == points[start] {
            return Ok(());
        }
        p = q;
    }
    Err(Error::Config(
        "gift wrapping did not close (non-finite coordinates?)",
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn square_with_inner_and_edge_points() {
        let pts = [
            Vec2::new(0.0, 0.0),
            Vec2::new(2.0, 0.0),
            Vec2::new(1.0, 0.0), // on an edge
            Vec2::new(2.0, 2.0),
            Vec2::new(1.0, 1.0), // inside
            Vec2::new(0.0, 2.0),
            Vec2::new(2.0, 2.0), // duplicate
        ];
        let mut out = heapless::Vec::<u16, 8>::new();
        gift_wrap(&pts, &mut out).unwrap();
        assert_eq!(out.as_slice(), &[0, 1, 3, 5]);
    }

    #[test]
    fn degenerate_inputs() {
        let mut out = heapless::Vec::<u16, 8>::new();
        gift_wrap(&[], &mut out).unwrap();
        assert!(out.is_empty());
        gift_wrap(&[Vec2::new(1.0, 1.0); 3], &mut out).unwrap();
        assert_eq!(out.as_slice(), &[0]);
        let line = [
            Vec2::new(0.0, 0.0),
            Vec2::new(1.0, 1.0),
            Vec2::new(2.0, 2.0),
        ];
        gift_wrap(&line, &mut out).unwrap();
        assert_eq!(out.as_slice(), &[0, 2]);
        let mut small = heapless::Vec::<u16, 2>::new();
        let tri = [
            Vec2::new(0.0, 0.0),
            Vec2::new(1.0, 0.0),
            Vec2::new(0.0, 1.0),
        ];
        assert_eq!(
            gift_wrap(&tri, &mut small),
            Err(Error::Capacity { capacity: 2 })
        );
    }
}
