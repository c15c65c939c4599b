//! A 4-ary min-heap of small `Copy` items.
//!
//! The edge queue of the simplifier holds tens of thousands of 16-byte entries, most of them
//! stale (lazy deletion), and popping dominates if each level is a cache miss: four children per
//! node halve the depth of a binary heap and put the siblings in one or two cache lines
//! (the usual d-ary heap trade-off, e.g. LaMarca & Ladner, "The Influence of Caches on the
//! Performance of Heaps", JEA 1996). Items equal under `Ord` pop in an unspecified but
//! deterministic order.

pub(crate) struct MinHeap<T> {
    items: Vec<T>,
}

impl<T: Ord + Copy> MinHeap<T> {
    pub(crate) fn with_capacity(capacity: usize) -> Self {
        Self {
            items: Vec::with_capacity(capacity),
        }
    }

    pub(crate) fn push(&mut self, item: T) {
        let mut i = self.items.len();
        self.items.push(item);
        while i > 0 {
            let parent = (i - 1) / 4;
            if item < self.items[parent] {
                self.items[i] = self.items[parent];
                i = parent;
            } else {
                break;
            }
        }
        self.items[i] = item;
    }

    pub(crate) fn len(&self) -> usize {
        self.items.len()
    }

    /// Drops every item for which `keep` is false, then restores the heap order bottom-up
    /// (Floyd's heap construction, linear in the length).
    pub(crate) fn retain(&mut self, keep: impl FnMut(&T) -> bool) {
        self.items.retain(keep);
        let len = self.items.len();
        for start in (0..len.div_ceil(4)).rev() {
            let item = self.items[start];
            let mut i = start;
            loop {
                let first = 4 * i + 1;
                let Some((k, &smallest)) = self
                    .items
                    .get(first..len.min(first + 4))
                    .and_then(|c| c.iter().enumerate().min_by_key(|&(_, x)| *x))
                else {
                    break;
                };
                if smallest < item {
                    self.items[i] = smallest;
                    i = first + k;
                } else {
                    break;
                }
            }
            self.items[i] = item;
        }
    }

    /// The smallest item, without removing it.
    pub(crate) fn peek(&self) -> Option<T> {
        self.items.first().copied()
    }

    pub(crate) fn pop(&mut self) -> Option<T> {
        let last = self.items.pop()?;
        let Some(&top) = self.items.first() else {
            return Some(last);
        };
        let len = self.items.len();
        let mut i = 0;
        loop {
            let first = 4 * i + 1;
            let (child, smallest) = if let Some(c) = self.items.get(first..first + 4) {
                // The common case: four children, compared as a small tournament.
                let (i01, m01) = if c[1] < c[0] { (1, c[1]) } else { (0, c[0]) };
                let (i23, m23) = if c[3] < c[2] { (3, c[3]) } else { (2, c[2]) };
                if m23 < m01 {
                    (i23, m23)
                } else {
                    (i01, m01)
                }
            } else if let Some(c) = self.items.get(first..len) {
                match c.iter().enumerate().min_by_key(|&(_, item)| *item) {
                    Some((k, &item)) => (k, item),
                    None => break,
                }
            } else {
                break;
            };
            if smallest < last {
                self.items[i] = smallest;
                i = first + child;
            } else {
                break;
            }
        }
        self.items[i] = last;
        Some(top)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pops_in_ascending_order() {
        let mut heap = MinHeap::with_capacity(4);
        let mut state = 99u32;
        let mut expected = Vec::new();
        for round in 0..5 {
            for _ in 0..200 {
                state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                heap.push(state >> 8);
                expected.push(state >> 8);
            }
            expected.sort_unstable_by(|a, b| b.cmp(a));
            for _ in 0..(100 + round) {
                assert_eq!(heap.pop(), expected.pop());
            }
        }
        while let Some(x) = heap.pop() {
            assert_eq!(Some(x), expected.pop());
        }
        assert!(expected.is_empty());
    }

    #[test]
    fn retain_keeps_heap_order() {
        let mut heap = MinHeap::with_capacity(4);
        let mut state = 7u32;
        for _ in 0..1000 {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            heap.push(state >> 8);
        }
        heap.retain(|x| x % 3 != 0);
        let mut last = 0;
        let mut count = 0;
        while let Some(x) = heap.pop() {
            assert!(x >= last && x % 3 != 0);
            last = x;
            count += 1;
        }
        assert!(count > 500 && count < 800, "{count}");
    }
}
