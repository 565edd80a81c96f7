//! Minimum spanning tree of the skeleton key points (Prim's algorithm on the complete
//! graph, Euclidean weights, paper Eq. 3), and the tree queries the skeleton needs.
//!
//! Prim's dense form runs in `O(n²)` time and `O(n)` memory, the best choice for a
//! complete graph: no edge list is ever stored. Node indices are `u8`, so a tree holds
//! at most [`MAX_TREE_NODES`] nodes.

use crate::error::{Error, Result};
use crate::limits::MAX_TREE_NODES;
use crate::Vec3;

/// A spanning tree over up to `N` points stored as parent links (node 0 is the root).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Tree<const N: usize> {
    parent: [u8; N],
    len: usize,
}

impl<const N: usize> Default for Tree<N> {
    /// The empty tree (no nodes).
    fn default() -> Self {
        Tree {
            parent: [0; N],
            len: 0,
        }
    }
}

impl<const N: usize> Tree<N> {
    /// Prim's MST of `points` (1..=N of them, N ≤ 255) rooted at point 0. Ties between
    /// equal edges go to the lower index, so the tree is deterministic.
    pub fn prim(points: &[Vec3]) -> Result<Self> {
        let n = points.len();
        if n == 0 || n > N || N > MAX_TREE_NODES {
            return Err(Error::Config("tree size must be 1..=N, N <= 255"));
        }
        let mut parent = [0u8; N];
        let mut best = [f32::INFINITY; N];
        let mut done = [false; N];
        best[0] = 0.0;
        for _ in 0..n {
            // Cheapest node not yet in the tree.
            let mut u = usize::MAX;
            let mut bu = f32::INFINITY;
            for v in 0..n {
                if !done[v] && (u == usize::MAX || best[v] < bu) {
                    u = v;
                    bu = best[v];
                }
            }
            done[u] = true;
            for v in 0..n {
                if !done[v] {
                    let d = (points[u] - points[v]).norm();
                    if d < best[v] {
                        best[v] = d;
                        parent[v] = u as u8; // u < N <= 255
                    }
                }
            }
        }
        Ok(Tree { parent, len: n })
    }

    /// Number of nodes.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True for a tree without nodes (never built by [`Tree::prim`]).
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Parent of `v` (the root is its own parent).
    pub fn parent(&self, v: usize) -> usize {
        usize::from(self.parent[v])
    }

    /// The `len − 1` edges as (child, parent) pairs, in node order.
    pub fn edges(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        (1..self.len).map(|v| (v, self.parent(v)))
    }

    /// Total Euclidean length of the tree over the `points` it was built on.
    pub fn weight(&self, points: &[Vec3]) -> f32 {
        self.edges()
            .map(|(a, b)| (points[a] - points[b]).norm())
            .sum()
    }

    /// Number of edges at each node.
    pub fn degrees(&self) -> [u8; N] {
        let mut deg = [0u8; N];
        for (a, b) in self.edges() {
            deg[a] = deg[a].saturating_add(1);
            deg[b] = deg[b].saturating_add(1);
        }
        deg
    }

    fn depth(&self, mut v: usize) -> usize {
        let mut d = 0;
        while v != 0 && d < N {
            v = self.parent(v);
            d += 1;
        }
        d
    }

    /// The unique tree path from `a` to `b`, both included, written into `out`.
    pub fn path(&self, a: usize, b: usize, out: &mut heapless::Vec<u8, N>) -> Result<()> {
        out.clear();
        if a >= self.len || b >= self.len {
            return Err(Error::Config("path end is not a tree node"));
        }
        let (mut x, mut y) = (a, b);
        let (mut dx, mut dy) = (self.depth(a), self.depth(b));
        // Climb from both ends to the lowest common ancestor; the `a` side is written
        // directly, the `b` side is collected and appended reversed.
        let mut tail = heapless::Vec::<u8, N>::new();
        let full = Error::Capacity { capacity: N as u32 };
        while dx > dy {
            out.push(x as u8).map_err(|_| full)?;
            x = self.parent(x);
            dx -= 1;
        }
        while dy > dx {
            tail.push(y as u8).map_err(|_| full)?;
            y = self.parent(y);
            dy -= 1;
        }
        while x != y {
            out.push(x as u8).map_err(|_| full)?;
            tail.push(y as u8).map_err(|_| full)?;
            x = self.parent(x);
            y = self.parent(y);
        }
        out.push(x as u8).map_err(|_| full)?;
        for &v in tail.iter().rev() {
            out.push(v).map_err(|_| full)?;
        }
        Ok(())
    }

    /// Length along the tree from leaf `v` to the first node with degree ≠ 2 (a branch
    /// point or another leaf): how long the branch ending in `v` is.
    pub fn branch_length(&self, v: usize, points: &[Vec3], degrees: &[u8; N]) -> f32 {
        let (mut prev, mut cur) = (usize::MAX, v);
        let mut len = 0.0;
        for _ in 0..N {
            let next = self.neighbours(cur).find(|&w| w != prev);
            let Some(next) = next else { break };
            len += (points[cur] - points[next]).norm();
            prev = cur;
            cur = next;
            if degrees[cur] != 2 {
                break;
            }
        }
        len
    }

    /// Neighbours of `v` in the tree.
    pub fn neighbours(&self, v: usize) -> impl Iterator<Item = usize> + '_ {
        let up = (v != 0).then(|| self.parent(v));
        up.into_iter()
            .chain((1..self.len).filter(move |&w| self.parent(w) == v))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_of_points_gives_a_chain() {
        let pts: [Vec3; 6] =
            core::array::from_fn(|i| Vec3::new([0., 5., 1., 4., 2., 3.][i], 0., 0.));
        let t = Tree::<6>::prim(&pts).unwrap();
        assert!((t.weight(&pts) - 5.0).abs() < 1e-6);
        let deg = t.degrees();
        assert_eq!(deg.iter().filter(|&&d| d == 1).count(), 2);
        let mut path = heapless::Vec::new();
        t.path(0, 1, &mut path).unwrap();
        assert_eq!(path.as_slice(), &[0, 2, 4, 5, 3, 1]);
        t.path(3, 3, &mut path).unwrap();
        assert_eq!(path.as_slice(), &[3]);
        assert!((t.branch_length(0, &pts, &deg) - 5.0).abs() < 1e-6);
    }

    #[test]
    fn star_branches() {
        // Centre 0 with arms of length 1, 2 and 3 (two nodes on the long arm).
        let pts = [
            Vec3::zeros(),
            Vec3::new(1., 0., 0.),
            Vec3::new(0., 2., 0.),
            Vec3::new(0., 0., -1.5),
            Vec3::new(0., 0., -3.),
        ];
        let t = Tree::<8>::prim(&pts).unwrap();
        let deg = t.degrees();
        assert_eq!(deg, [3, 1, 1, 2, 1, 0, 0, 0]);
        assert!(Tree::<4>::prim(&pts).is_err());
        assert!(Tree::<4>::prim(&[]).is_err());
        assert!((t.branch_length(4, &pts, &deg) - 3.0).abs() < 1e-6);
        assert!((t.branch_length(2, &pts, &deg) - 2.0).abs() < 1e-6);
        let mut path = heapless::Vec::new();
        t.path(4, 2, &mut path).unwrap();
        assert_eq!(path.as_slice(), &[4, 3, 0, 2]);
        assert_eq!(t.neighbours(0).count(), 3);
    }
}
