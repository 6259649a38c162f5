//! A fixed-capacity min-heap on the stack, keyed by `f64`, for the best-first front-facing
//! search (no allocation per query).

/// Min-heap of at most `N` items ordered by their `f64` key (NaN keys sort last).
pub(crate) struct BoundedHeap<T: Copy, const N: usize> {
    keys: [f64; N],
    items: [T; N],
    len: usize,
}

impl<T: Copy, const N: usize> BoundedHeap<T, N> {
    /// An empty heap; `fill` initialises the unused slots.
    pub(crate) fn new(fill: T) -> Self {
        Self {
            keys: [f64::INFINITY; N],
            items: [fill; N],
            len: 0,
        }
    }

    /// Inserts `item`, or hands it back when the heap is full.
    pub(crate) fn push(&mut self, key: f64, item: T) -> Result<(), T> {
        if self.len == N {
            return Err(item);
        }
        let mut i = self.len;
        self.len += 1;
        while i > 0 {
            let parent = (i - 1) / 2;
            if self.keys[parent].total_cmp(&key).is_le() {
                break;
            }
            self.keys[i] = self.keys[parent];
            self.items[i] = self.items[parent];
            i = parent;
        }
        self.keys[i] = key;
        self.items[i] = item;
        Ok(())
    }

    /// The smallest key, if any.
    pub(crate) fn peek_key(&self) -> Option<f64> {
        (self.len > 0).then(|| self.keys[0])
    }

    /// Removes and returns the item with the smallest key.
    pub(crate) fn pop(&mut self) -> Option<(f64, T)> {
        if self.len == 0 {
            return None;
        }
        let top = (self.keys[0], self.items[0]);
        self.len -= 1;
        let (key, item) = (self.keys[self.len], self.items[self.len]);
        let mut i = 0;
        loop {
            let left = 2 * i + 1;
            if left >= self.len {
                break;
            }
            let right = left + 1;
            let child = if right < self.len && self.keys[right].total_cmp(&self.keys[left]).is_lt() {
                right
            } else {
                left
            };
            if key.total_cmp(&self.keys[child]).is_le() {
                break;
            }
            self.keys[i] = self.keys[child];
            self.items[i] = self.items[child];
            i = child;
        }
        self.keys[i] = key;
        self.items[i] = item;
        Some(top)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pops_in_key_order_and_refuses_overflow() {
        let mut h: BoundedHeap<u32, 8> = BoundedHeap::new(0);
        for (k, v) in [5.0, 1.0, 4.0, 1.5, 9.0, 0.5, 3.0, 2.0].iter().zip(0u32..) {
            assert!(h.push(*k, v).is_ok());
        }
        assert_eq!(h.push(0.1, 99), Err(99));
        let mut keys = vec![];
        while let Some((k, _)) = h.pop() {
            keys.push(k);
        }
        assert_eq!(keys, vec![0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 9.0]);
        assert!(h.peek_key().is_none());
    }
}
