//! The triangle list of one vertex in the decimation state: inline up to
//! [`INLINE_TRIANGLES`] entries, on the heap beyond, read as a slice.

/// Triangles a vertex keeps inline; more go to the heap. Marching-cubes vertices start
/// with 4–8 and decimation keeps the average near 6, so most lists never allocate.
pub(super) const INLINE_TRIANGLES: usize = 8;

/// The triangles of one vertex: a list that lives inline up to [`INLINE_TRIANGLES`]
/// entries (no allocation per vertex, and the list sits beside its neighbours' in
/// memory), on the heap beyond.
#[derive(Clone, Default)]
pub(super) struct TriList {
    len: u32,
    inline: [u32; INLINE_TRIANGLES],
    heap: Vec<u32>,
}

impl TriList {
    pub(super) fn from_slice(tris: &[u32]) -> TriList {
        let mut list = TriList::default();
        if tris.len() <= INLINE_TRIANGLES {
            list.inline[..tris.len()].copy_from_slice(tris);
        } else {
            list.heap = tris.to_vec();
        }
        list.len = tris.len() as u32;
        list
    }

    pub(super) fn spilled(&self) -> bool {
        !self.heap.is_empty()
    }

    pub(super) fn push(&mut self, t: u32) {
        let n = self.len as usize;
        if self.spilled() {
            self.heap.push(t);
        } else if n < INLINE_TRIANGLES {
            self.inline[n] = t;
        } else {
            self.heap = Vec::with_capacity(2 * INLINE_TRIANGLES);
            self.heap.extend_from_slice(&self.inline);
            self.heap.push(t);
        }
        self.len += 1;
    }

    pub(super) fn retain(&mut self, keep: impl Fn(&u32) -> bool) {
        if self.spilled() {
            self.heap.retain(keep);
            self.len = self.heap.len() as u32;
            if self.heap.is_empty() {
                self.heap = Vec::new();
            }
        } else {
            let mut kept = 0;
            for k in 0..self.len as usize {
                if keep(&self.inline[k]) {
                    self.inline[kept] = self.inline[k];
                    kept += 1;
                }
            }
            self.len = kept as u32;
        }
    }
}

impl std::ops::Deref for TriList {
    type Target = [u32];
    fn deref(&self) -> &[u32] {
        if self.spilled() {
            &self.heap
        } else {
            &self.inline[..self.len as usize]
        }
    }
}

impl<'a> IntoIterator for &'a TriList {
    type Item = &'a u32;
    type IntoIter = std::slice::Iter<'a, u32>;
    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triangle_lists_behave_like_vectors_across_the_inline_limit() {
        let mut list = TriList::from_slice(&[1, 2, 3]);
        let mut reference = vec![1u32, 2, 3];
        // Grow past the inline capacity, shrink back under it, and grow again.
        for t in 4..20 {
            list.push(t);
            reference.push(t);
            assert_eq!(&*list, reference.as_slice());
        }
        list.retain(|&t| t % 3 == 0);
        reference.retain(|&t| t % 3 == 0);
        assert_eq!(&*list, reference.as_slice());
        list.retain(|_| false);
        assert!(list.is_empty() && !list.spilled());
        for t in 0..INLINE_TRIANGLES as u32 + 2 {
            list.push(t);
        }
        assert_eq!(list.len(), INLINE_TRIANGLES + 2);
        assert_eq!(
            list.iter().copied().max(),
            Some(INLINE_TRIANGLES as u32 + 1)
        );
        let big = TriList::from_slice(&(0..12).collect::<Vec<u32>>());
        assert!(big.spilled() && big.len() == 12);
        assert_eq!(std::mem::take(&mut list).len(), INLINE_TRIANGLES + 2);
        assert!(list.is_empty());
    }
}
