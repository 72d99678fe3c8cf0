//! An octree over cache records for "which records lie within r of x" (Ward et al. 1988 keep
//! their irradiance cache in one). A record lives in the deepest node that contains its
//! position and is at least `2r` wide, so a query visits only nodes within r of x. Nodes split
//! lazily.
use glam::Vec3;

#[derive(Clone, Debug)]
struct Node<T> {
    centre: Vec3,
    half: f32,
    /// Indices of the eight children in `nodes`, once split.
    children: Option<[u32; 8]>,
    items: Vec<T>,
}

/// Deepest level below the root; a query's stack holds at most 7 per level plus one.
const MAX_DEPTH: u32 = 32;
const QUERY_STACK: usize = 7 * MAX_DEPTH as usize + 8;

/// Items of type `T` (kept inline, so a query reads them without chasing indices) by position.
#[derive(Clone, Debug)]
pub struct Octree<T> {
    nodes: Vec<Node<T>>,
    /// Smallest node half-width: a record's influence radius.
    min_half: f32,
}

impl<T: Copy> Octree<T> {
    /// An empty octree over the cube of half-width `half` around `centre`, for query radius `r`.
    pub fn new(centre: Vec3, half: f32, r: f32) -> Octree<T> {
        let half = half.max(r);
        let root = Node { centre, half, children: None, items: Vec::new() };
        // At most MAX_DEPTH levels, so a query's stack stays within QUERY_STACK.
        Octree { nodes: vec![root], min_half: r.max(half / (1u64 << MAX_DEPTH) as f32) }
    }

    pub fn clear(&mut self) {
        self.nodes.truncate(1);
        self.nodes[0].children = None;
        self.nodes[0].items.clear();
    }

    /// Inserts `item` at `p`. Points outside the root go to the root.
    pub fn insert(&mut self, item: T, p: Vec3) {
        let mut at = 0usize;
        loop {
            let (centre, half) = (self.nodes[at].centre, self.nodes[at].half);
            let inside = (p - centre).abs().max_element() <= half;
            if !inside || half * 0.5 < self.min_half {
                self.nodes[at].items.push(item);
                return;
            }
            let children = match self.nodes[at].children {
                Some(c) => c,
                None => {
                    let first = self.nodes.len() as u32;
                    for k in 0..8u32 {
                        let offset = Vec3::new(
                            if k & 1 != 0 { 0.5 } else { -0.5 },
                            if k & 2 != 0 { 0.5 } else { -0.5 },
                            if k & 4 != 0 { 0.5 } else { -0.5 },
                        ) * half;
                        self.nodes.push(Node {
                            centre: centre + offset,
                            half: half * 0.5,
                            children: None,
                            items: Vec::new(),
                        });
                    }
                    let c = std::array::from_fn(|k| first + k as u32);
                    self.nodes[at].children = Some(c);
                    c
                }
            };
            let k =
                usize::from(p.x >= centre.x) | usize::from(p.y >= centre.y) << 1 | usize::from(p.z >= centre.z) << 2;
            at = children[k] as usize;
        }
    }

    /// Calls `f` with every item whose position may lie within `r` of `p` (a superset; the
    /// caller tests the distance) until `f` returns false. Returns false if it was stopped.
    pub fn query(&self, p: Vec3, r: f32, mut f: impl FnMut(&T) -> bool) -> bool {
        let mut stack = [0u32; QUERY_STACK];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let at = stack[top] as usize;
            let n = &self.nodes[at];
            // A node's records lie inside it, except the root's strays: test the root always.
            if at != 0 && ((p - n.centre).abs() - Vec3::splat(n.half)).max(Vec3::ZERO).length() > r {
                continue;
            }
            if !n.items.iter().all(&mut f) {
                return false;
            }
            if let Some(c) = n.children {
                stack[top..top + 8].copy_from_slice(&c);
                top += 8;
            }
        }
        true
    }

    pub fn memory_bytes(&self) -> u64 {
        self.nodes
            .iter()
            .map(|n| (std::mem::size_of::<Node<T>>() + n.items.len() * std::mem::size_of::<T>()) as u64)
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn queries_agree_with_brute_force_on_random_records() {
        let mut rng = crate::core::Rng::new(7, 8);
        let mut v = || rng.next_f32() * 20.0 - 10.0;
        let r = 0.7;
        let points: Vec<Vec3> = (0..3000).map(|_| Vec3::new(v(), v(), v())).collect();
        let mut tree = Octree::new(Vec3::ZERO, 8.0, r);
        for (i, p) in points.iter().enumerate() {
            tree.insert(i as u32, *p);
        }
        let mut all = 0;
        tree.query(Vec3::ZERO, 1e9, |_: &u32| {
            all += 1;
            true
        });
        assert_eq!(all, points.len(), "every record is reachable");
        for _ in 0..500 {
            let q = Vec3::new(v(), v(), v());
            let mut found: Vec<u32> = Vec::new();
            tree.query(q, r, |&i| {
                if (points[i as usize] - q).length() <= r {
                    found.push(i)
                }
                true
            });
            found.sort_unstable();
            let brute: Vec<u32> =
                (0..points.len() as u32).filter(|&i| (points[i as usize] - q).length() <= r).collect();
            assert_eq!(found, brute, "query at {q:?}");
        }
    }
}
