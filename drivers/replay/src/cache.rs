//! The decoded frames of a looped replay, kept in memory so that later passes copy them
//! instead of reading and decoding their files again.
//!
//! Entry point: [`FrameCache::get_or_decode`], shared by [`crate::ImageSequence`] (a frame's
//! depth in metres) and [`crate::CloudSequence`] (a file's cloud and grid).
//!
//! A looped replay plays the same files pass after pass. Reading and decoding them again (an
//! LZF-compressed 640x480 PCD, a PNG or TIFF) took the source thread about 30 % of the
//! daemon's CPU on the milk scene, on two cores shared with segmenting and fusing. So the first
//! pass keeps each decoded frame while the total stays within a budget,
//! [`DEFAULT_LOOP_CACHE_BYTES`] (64 MiB) unless configured: a 640x480 cloud is 3.5 MiB, a
//! 640x480 depth image 1.2 MiB, so a one-file recording, the eight labelled scans or a
//! fifty-frame image sequence fit. Frames past the budget are decoded on every pass, as without
//! a cache. A frame that fails to decode is never kept: it is reported on every pass, as it
//! would be without a cache. A replay that does not loop plays each frame once and keeps
//! nothing (its budget is 0).

/// The memory a looped replay may keep decoded frames in, by default: 64 MiB.
pub const DEFAULT_LOOP_CACHE_BYTES: usize = 64 << 20;

/// What a kept frame costs: the bytes its buffers hold on the heap.
pub(crate) trait HeapBytes {
    fn heap_bytes(&self) -> usize;
}

impl<T> HeapBytes for Vec<T> {
    fn heap_bytes(&self) -> usize {
        self.capacity() * std::mem::size_of::<T>()
    }
}

/// Decoded frames by index in the replay's file list, within a byte budget.
#[derive(Debug)]
pub(crate) struct FrameCache<T> {
    frames: Vec<Option<T>>,
    used_bytes: usize,
    budget_bytes: usize,
    /// A frame did not fit (said once, at INFO).
    full: bool,
}

impl<T: Clone + HeapBytes> FrameCache<T> {
    /// A cache for `len` frames that keeps at most `budget_bytes` of them (0: none).
    pub(crate) fn new(len: usize, budget_bytes: usize) -> Self {
        Self {
            frames: vec![None; len],
            used_bytes: 0,
            budget_bytes,
            full: false,
        }
    }

    /// Frame `index`: a copy of the kept one, or else `decode()`'s, kept when it fits in the
    /// budget. An error is returned and nothing is kept. `name` is the replay's, for the log.
    pub(crate) fn get_or_decode<E>(
        &mut self,
        index: usize,
        name: &str,
        decode: impl FnOnce() -> Result<T, E>,
    ) -> Result<T, E> {
        if let Some(frame) = self.frames.get(index).and_then(Option::as_ref) {
            return Ok(frame.clone());
        }
        let frame = decode()?;
        if self.budget_bytes == 0 || index >= self.frames.len() {
            return Ok(frame);
        }
        // The copy is the one kept: its buffers are exactly as long as the frame.
        let kept = frame.clone();
        let bytes = kept.heap_bytes();
        if self.used_bytes + bytes <= self.budget_bytes {
            self.used_bytes += bytes;
            self.frames[index] = Some(kept);
        } else if !self.full {
            self.full = true;
            tracing::info!(
                "{name}: keeps {} decoded frames ({:.1} MiB) in memory for its later passes; \
                 frame {index} and any other past the {:.0} MiB budget are decoded on every pass",
                self.kept(),
                self.used_bytes as f64 / f64::from(1 << 20),
                self.budget_bytes as f64 / f64::from(1 << 20),
            );
        }
        Ok(frame)
    }

    /// How many frames are kept.
    pub(crate) fn kept(&self) -> usize {
        self.frames.iter().filter(|f| f.is_some()).count()
    }

    /// How many bytes the kept frames hold.
    #[cfg(test)]
    pub(crate) fn used_bytes(&self) -> usize {
        self.used_bytes
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Decodes frame `index` as `[index; len]`, counting the decodes.
    fn decoder(decodes: &mut usize, index: usize, len: usize) -> Result<Vec<u8>, String> {
        *decodes += 1;
        Ok(vec![index as u8; len])
    }

    #[test]
    fn a_kept_frame_is_copied_not_decoded_again() {
        let mut cache = FrameCache::new(2, 1000);
        let mut decodes = 0;
        let first: Vec<_> = (0..2)
            .map(|i| cache.get_or_decode(i, "t", || decoder(&mut decodes, i, 10)))
            .collect();
        let second: Vec<_> = (0..2)
            .map(|i| cache.get_or_decode(i, "t", || decoder(&mut decodes, i, 10)))
            .collect();
        assert_eq!(first, second);
        assert_eq!((decodes, cache.kept(), cache.used_bytes()), (2, 2, 20));
    }

    #[test]
    fn frames_past_the_budget_are_decoded_every_time() {
        // Room for two 40-byte frames of three.
        let mut cache = FrameCache::new(3, 100);
        let mut decodes = 0;
        for _pass in 0..3 {
            for i in 0..3 {
                let frame = cache
                    .get_or_decode(i, "t", || decoder(&mut decodes, i, 40))
                    .expect("decodes");
                assert_eq!(frame, vec![i as u8; 40]);
            }
        }
        assert_eq!((cache.kept(), cache.used_bytes()), (2, 80));
        assert_eq!(decodes, 3 + 1 + 1);
    }

    #[test]
    fn a_zero_budget_keeps_nothing() {
        let mut cache = FrameCache::new(1, 0);
        let mut decodes = 0;
        for _ in 0..2 {
            cache
                .get_or_decode(0, "t", || decoder(&mut decodes, 0, 1))
                .expect("decodes");
        }
        assert_eq!((decodes, cache.kept()), (2, 0));
    }

    #[test]
    fn an_error_is_not_kept() {
        let mut cache = FrameCache::<Vec<u8>>::new(1, 1000);
        let mut attempts = 0;
        for _ in 0..2 {
            let result = cache.get_or_decode(0, "t", || {
                attempts += 1;
                Err::<Vec<u8>, _>("corrupt")
            });
            assert_eq!(result, Err("corrupt"));
        }
        assert_eq!((attempts, cache.kept()), (2, 0));
    }
}
