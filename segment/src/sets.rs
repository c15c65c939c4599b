//! Disjoint sets with path halving and union by weight: clustering's components, the
//! convexity split's pieces and the occlusion joins all merge sets of items so.

/// Disjoint sets of items `0..n`, each set weighing the sum of its items' weights.
pub(crate) struct DisjointSets {
    parent: Vec<u32>,
    /// The weight of each set, at its root (a non-root's entry is stale).
    pub(crate) weight: Vec<usize>,
}

impl DisjointSets {
    /// Each item alone, weighing `weights[i]`.
    pub(crate) fn new(weights: Vec<usize>) -> Self {
        Self {
            parent: (0..weights.len() as u32).collect(),
            weight: weights,
        }
    }

    /// `n` items alone, each weighing one.
    pub(crate) fn singletons(n: usize) -> Self {
        Self::new(vec![1; n])
    }

    /// The root of `x`'s set.
    pub(crate) fn find(&mut self, mut x: u32) -> u32 {
        while self.parent[x as usize] != x {
            let grandparent = self.parent[self.parent[x as usize] as usize];
            self.parent[x as usize] = grandparent;
            x = grandparent;
        }
        x
    }

    /// Merges the sets of `a` and `b` under the heavier one's root; returns the root.
    pub(crate) fn union(&mut self, a: u32, b: u32) -> u32 {
        let (mut a, mut b) = (self.find(a), self.find(b));
        if a == b {
            return a;
        }
        if self.weight[a as usize] < self.weight[b as usize] {
            std::mem::swap(&mut a, &mut b);
        }
        self.parent[b as usize] = a;
        self.weight[a as usize] += self.weight[b as usize];
        a
    }
}
