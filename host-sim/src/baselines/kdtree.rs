//! A small f64 k-d tree answering nearest-*index* and k-nearest queries.
//!
//! Built once over a borrowed copy of the points (median splits on the axis of largest
//! spread, leaves of up to `LEAF_SIZE` = 8 points). Queries are exact. Ties in distance are
//! broken toward the smaller point index, so every query has one deterministic answer
//! whatever the tree's shape.

/// Points per leaf.
const LEAF_SIZE: usize = 8;

#[derive(Clone, Debug)]
enum Node {
    /// `idx[start..end]` are the points of the leaf.
    Leaf { start: usize, end: usize },
    /// Points with `p[axis] <= split` are on the left.
    Split {
        axis: usize,
        split: f64,
        left: usize,
        right: usize,
    },
}

/// Exact nearest-neighbour search over a fixed set of 3-D points.
#[derive(Clone, Debug)]
pub struct KdTree {
    points: Vec<[f64; 3]>,
    idx: Vec<usize>,
    nodes: Vec<Node>,
}

fn dist2(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
}

/// `(d², index)` ordering with the index as tie-break.
fn better(a: (f64, usize), b: (f64, usize)) -> bool {
    a.0 < b.0 || (a.0 == b.0 && a.1 < b.1)
}

impl KdTree {
    /// A tree over `points` (copied). The points must be finite (callers validate).
    pub fn new(points: &[[f64; 3]]) -> Self {
        let mut tree = KdTree {
            points: points.to_vec(),
            idx: (0..points.len()).collect(),
            nodes: Vec::with_capacity(2 * points.len() / LEAF_SIZE + 1),
        };
        if !points.is_empty() {
            tree.build(0, points.len());
        }
        tree
    }

    /// Number of points in the tree.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// `true` when the tree holds no point.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The indexed points.
    pub fn points(&self) -> &[[f64; 3]] {
        &self.points
    }

    fn build(&mut self, start: usize, end: usize) -> usize {
        let id = self.nodes.len();
        if end - start <= LEAF_SIZE {
            self.nodes.push(Node::Leaf { start, end });
            return id;
        }
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for &i in &self.idx[start..end] {
            for a in 0..3 {
                lo[a] = lo[a].min(self.points[i][a]);
                hi[a] = hi[a].max(self.points[i][a]);
            }
        }
        let axis = (0..3)
            .max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b])))
            .unwrap_or(0);
        if hi[axis] - lo[axis] <= 0.0 {
            // All points coincide: one (oversized) leaf.
            self.nodes.push(Node::Leaf { start, end });
            return id;
        }
        let mid = start + (end - start) / 2;
        let pts = &self.points;
        self.idx[start..end].select_nth_unstable_by(mid - start, |&a, &b| {
            pts[a][axis].total_cmp(&pts[b][axis]).then(a.cmp(&b))
        });
        let split = self.points[self.idx[mid]][axis];
        self.nodes.push(Node::Leaf { start, end }); // placeholder
        let left = self.build(start, mid + 1);
        let right = self.build(mid + 1, end);
        self.nodes[id] = Node::Split {
            axis,
            split,
            left,
            right,
        };
        id
    }

    /// The index of the point nearest to `q` and its squared distance, or `None` for an
    /// empty tree.
    pub fn nearest(&self, q: &[f64; 3]) -> Option<(usize, f64)> {
        if self.points.is_empty() {
            return None;
        }
        let mut best = (f64::INFINITY, usize::MAX);
        self.nearest_in(0, q, &mut best);
        Some((best.1, best.0))
    }

    fn nearest_in(&self, node: usize, q: &[f64; 3], best: &mut (f64, usize)) {
        match self.nodes[node] {
            Node::Leaf { start, end } => {
                for &i in &self.idx[start..end] {
                    let cand = (dist2(&self.points[i], q), i);
                    if better(cand, *best) {
                        *best = cand;
                    }
                }
            }
            Node::Split {
                axis,
                split,
                left,
                right,
            } => {
                let d = q[axis] - split;
                let (near, far) = if d <= 0.0 {
                    (left, right)
                } else {
                    (right, left)
                };
                self.nearest_in(near, q, best);
                if d * d <= best.0 {
                    self.nearest_in(far, q, best);
                }
            }
        }
    }

    /// The `k` points nearest to `q` as `(index, squared distance)`, closest first (fewer
    /// when the tree holds fewer than `k` points).
    pub fn k_nearest(&self, q: &[f64; 3], k: usize) -> Vec<(usize, f64)> {
        let mut heap: Vec<(f64, usize)> = Vec::with_capacity(k + 1);
        if k > 0 && !self.points.is_empty() {
            self.knn_in(0, q, k, &mut heap);
        }
        heap.into_iter().map(|(d, i)| (i, d)).collect()
    }

    /// `heap` is kept sorted, best first, at most `k` long.
    fn knn_in(&self, node: usize, q: &[f64; 3], k: usize, heap: &mut Vec<(f64, usize)>) {
        match self.nodes[node] {
            Node::Leaf { start, end } => {
                for &i in &self.idx[start..end] {
                    let cand = (dist2(&self.points[i], q), i);
                    if heap.len() == k && !better(cand, heap[k - 1]) {
                        continue;
                    }
                    let pos = heap.partition_point(|&h| better(h, cand));
                    heap.insert(pos, cand);
                    heap.truncate(k);
                }
            }
            Node::Split {
                axis,
                split,
                left,
                right,
            } => {
                let d = q[axis] - split;
                let (near, far) = if d <= 0.0 {
                    (left, right)
                } else {
                    (right, left)
                };
                self.knn_in(near, q, k, heap);
                if heap.len() < k || d * d <= heap[heap.len() - 1].0 {
                    self.knn_in(far, q, k, heap);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ribreg_core::math::rng::Rng;

    fn cloud(n: usize, seed: u64) -> Vec<[f64; 3]> {
        let mut rng = Rng::new(seed);
        (0..n)
            .map(|_| {
                [
                    rng.next_f64() * 100.0,
                    rng.next_f64() * 50.0,
                    rng.next_f64() * 10.0,
                ]
            })
            .collect()
    }

    #[test]
    fn kdtree_matches_brute_force() {
        let pts = cloud(700, 1);
        let tree = KdTree::new(&pts);
        for q in cloud(200, 2) {
            let brute = (0..pts.len()).map(|i| (dist2(&pts[i], &q), i)).fold(
                (f64::INFINITY, usize::MAX),
                |b, c| if better(c, b) { c } else { b },
            );
            let (i, d) = tree.nearest(&q).unwrap();
            assert_eq!((i, d), (brute.1, brute.0));
            let mut all: Vec<(f64, usize)> =
                (0..pts.len()).map(|i| (dist2(&pts[i], &q), i)).collect();
            all.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let knn = tree.k_nearest(&q, 7);
            let want: Vec<(usize, f64)> = all[..7].iter().map(|&(d, i)| (i, d)).collect();
            assert_eq!(knn, want);
        }
    }

    #[test]
    fn kdtree_duplicates_and_empty() {
        let pts = vec![[1.0, 2.0, 3.0]; 50];
        let tree = KdTree::new(&pts);
        assert_eq!(tree.nearest(&[0.0; 3]).unwrap().0, 0);
        assert_eq!(
            tree.k_nearest(&[0.0; 3], 3)
                .iter()
                .map(|x| x.0)
                .collect::<Vec<_>>(),
            vec![0, 1, 2]
        );
        let empty = KdTree::new(&[]);
        assert!(empty.nearest(&[0.0; 3]).is_none());
        assert!(empty.k_nearest(&[0.0; 3], 3).is_empty());
    }
}
