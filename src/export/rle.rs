//! Run-length encoded binary masks, bit-for-bit as pycocotools writes them.
//!
//! A COCO RLE lists the lengths of alternating runs of 0 and 1 over the mask in **column-major** order
//! (down the first column, then the second, …), always starting with a run of zeros (which may be
//! empty), with `size = [height, width]`. The compressed string form is pycocotools' `rleToString`: each
//! count (after the first two, the difference to the count two places earlier) is written as a signed
//! LEB128-like number in 5-bit groups, least significant first, each group offset by 48 into the
//! printable ASCII range `'0'..='o'` (bit 0x20 = "more groups follow").
//!
//! Everything here mirrors `maskApi.c` of pycocotools 2.0 (`rleEncode`, `rleDecode`, `rleArea`,
//! `rleToBbox`, `rleMerge`, `rleToString`, `rleFrString`), including its corner cases: an empty mask of
//! `h × w` is `[h·w]`, a full one `[0, h·w]`, a 0-pixel image `[0]`; a bounding box of an empty mask is
//! `[0, 0, 0, 0]`. The unit tests check the golden vectors produced by pycocotools; the integration test
//! `tests/it/coco_rle.rs` compares against `pycocotools.mask` live.
//!
//! Encoding works from row-major images (as rendered) without transposing anything: a column's runs
//! start and end exactly where the pixel differs from the one above, so one sequential pass comparing
//! each row with the previous one finds them all (see `for_each_column_run`). [`encode_labels`] appends
//! the runs of every label to its own RLE in that same pass, so a frame with hundreds of instances is
//! read once.
//!
//! # References
//! pycocotools `common/maskApi.c` (cocodataset/cocoapi), `PythonAPI/pycocotools/_mask.pyx`.

use std::fmt;

/// Pixels compared at a time when looking for changes between consecutive rows.
const CHUNK: usize = 64;

/// Longest compressed group sequence accepted for one count: 7 groups of 5 bits cover any u32 count and
/// any difference of two u32 counts (pycocotools' own decoder overflows a C `int` beyond that).
const MAX_GROUPS: usize = 7;

/// Errors from building or parsing an RLE.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RleError {
    /// The pixel buffer does not hold `height × width` values.
    #[error("mask buffer holds {len} values but size is {height}×{width} (height × width)")]
    BufferSize {
        /// Values in the buffer.
        len: usize,
        /// Mask height, pixels.
        height: u32,
        /// Mask width, pixels.
        width: u32,
    },
    /// A label image holds a label above the number of labels announced.
    #[error("label {label} at pixel (x={x}, y={y}) is above the {n_labels} labels announced")]
    LabelOutOfRange {
        /// The label found.
        label: u32,
        /// Labels announced.
        n_labels: usize,
        /// Pixel column.
        x: u32,
        /// Pixel row.
        y: u32,
    },
    /// A compressed RLE string holds a byte outside `'0'..='o'` (48..=111).
    #[error("compressed RLE has byte {byte:#04x} ({shown}) at offset {offset}; only '0'..='o' are valid")]
    BadChar {
        /// Byte offset in the string.
        offset: usize,
        /// The byte.
        byte: u8,
        /// The byte as printable text.
        shown: String,
    },
    /// The string ends inside a count (the last group had its "more" bit set).
    #[error("compressed RLE ends in the middle of a count (offset {offset})")]
    Truncated {
        /// Byte offset where the string ends.
        offset: usize,
    },
    /// A count does not fit in 32 bits or is negative.
    #[error("count #{index} decodes to {value}, outside 0..=4294967295")]
    CountOutOfRange {
        /// 0-based index of the count.
        index: usize,
        /// The value it decodes to.
        value: i64,
    },
    /// The counts do not cover the image exactly.
    #[error("counts sum to {sum} pixels but size {height}×{width} has {pixels}")]
    CountSum {
        /// Sum of the counts, pixels.
        sum: u64,
        /// Mask height, pixels.
        height: u32,
        /// Mask width, pixels.
        width: u32,
        /// height × width.
        pixels: u64,
    },
    /// Masks of different sizes were merged.
    #[error("cannot merge masks of size {a:?} and {b:?} ([height, width])")]
    MergeSize {
        /// `[height, width]` of one mask, pixels.
        a: [u32; 2],
        /// `[height, width]` of the other, pixels.
        b: [u32; 2],
    },
}

/// A run-length encoded binary mask (pycocotools' `RLE` struct).
///
/// `counts` alternate between runs of 0 and runs of 1, starting with 0, in column-major order; their
/// sum is `height × width` for every RLE built by this module.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Rle {
    /// `[height, width]` in pixels, as in COCO's `size`.
    pub size: [u32; 2],
    /// Run lengths in pixels.
    pub counts: Vec<u32>,
}

/// Accumulates the column-major runs of ones of one mask into pycocotools counts.
#[derive(Debug, Clone, Default)]
struct RleBuilder {
    counts: Vec<u32>,
    /// Column-major index just after the last run of ones.
    end: u64,
}

impl RleBuilder {
    #[inline]
    fn push_ones(&mut self, start: u64, len: u64) {
        if !self.counts.is_empty() && self.end == start {
            // A run ending at the bottom of one column continues at the top of the next.
            if let Some(last) = self.counts.last_mut() {
                *last += len as u32;
            }
        } else {
            self.counts.push((start - self.end) as u32);
            self.counts.push(len as u32);
        }
        self.end = start + len;
    }

    fn finish(mut self, height: u32, width: u32) -> Rle {
        let pixels = height as u64 * width as u64;
        if self.counts.is_empty() || self.end < pixels {
            self.counts.push((pixels - self.end) as u32);
        }
        Rle { size: [height, width], counts: self.counts }
    }
}

/// Calls `f(value, start, len)` for every maximal vertical run of equal values of a row-major image, in
/// column-major order; `start` is the column-major index of the run's first pixel.
///
/// No transposed copy is made: each row is compared with the row above — equal stretches (most of a
/// building map) are skipped [`CHUNK`] pixels at a time with a `memcmp` — and the rows where each column
/// changes value are bucketed per column (a counting sort, so they stay in increasing order). The runs
/// of a column then lie between consecutive change rows.
fn for_each_column_run<T: Copy + PartialEq>(
    data: &[T],
    height: usize,
    width: usize,
    mut f: impl FnMut(T, u64, u64),
) {
    if height == 0 || width == 0 {
        return;
    }
    let mut changes: Vec<(u32, u32)> = Vec::new(); // (x, y): the pixel differs from the one above
    let mut per_col = vec![0usize; width + 1];
    for y in 1..height {
        let above = &data[(y - 1) * width..y * width];
        let row = &data[y * width..(y + 1) * width];
        for (k, (ca, cb)) in above.chunks(CHUNK).zip(row.chunks(CHUNK)).enumerate() {
            if ca == cb {
                continue;
            }
            for (i, (a, b)) in ca.iter().zip(cb).enumerate() {
                if a != b {
                    let x = k * CHUNK + i;
                    changes.push((x as u32, y as u32));
                    per_col[x + 1] += 1;
                }
            }
        }
    }
    for x in 0..width {
        per_col[x + 1] += per_col[x];
    }
    let mut next = per_col.clone();
    let mut rows = vec![0u32; changes.len()];
    for &(x, y) in &changes {
        rows[next[x as usize]] = y;
        next[x as usize] += 1;
    }
    for x in 0..width {
        let base = (x * height) as u64;
        let (mut start, mut v) = (0usize, data[x]);
        for &y in &rows[per_col[x]..per_col[x + 1]] {
            let y = y as usize;
            f(v, base + start as u64, (y - start) as u64);
            start = y;
            v = data[y * width + x];
        }
        f(v, base + start as u64, (height - start) as u64);
    }
}

fn check_len(len: usize, height: u32, width: u32) -> Result<(), RleError> {
    if len as u64 != height as u64 * width as u64 {
        return Err(RleError::BufferSize { len, height, width });
    }
    Ok(())
}

/// Encodes a row-major binary mask (one byte per pixel, non-zero = inside) — `pycocotools.mask.encode`
/// of the same mask as a 0/1 array.
///
/// ```
/// // A 3 × 2 px block in a 4 × 5 px image (golden vector `rect_4x5`, from pycocotools).
/// let mask = [0, 0, 0, 0, 0, //
///             0, 1, 1, 1, 0, //
///             0, 1, 1, 1, 0, //
///             0, 0, 0, 0, 0u8];
/// let rle = insgen::export::rle::encode(&mask, 4, 5).unwrap();
/// assert_eq!(rle.counts, [5, 2, 2, 2, 2, 2, 5]); // column-major runs, zeros first
/// assert_eq!(rle.to_string(), "5220003");
/// assert_eq!((rle.area(), rle.to_bbox()), (6, [1.0, 1.0, 3.0, 2.0])); // px, [x, y, w, h] px
/// ```
///
/// pycocotools starts a new run at every change of byte value, so it must be given 0/1 masks; here every
/// non-zero byte counts as 1.
///
/// # Errors
/// [`RleError::BufferSize`] when `mask.len() != height × width`.
pub fn encode(mask: &[u8], height: u32, width: u32) -> Result<Rle, RleError> {
    check_len(mask.len(), height, width)?;
    let mut b = RleBuilder::default();
    for_each_column_run(mask, height as usize, width as usize, |v, start, len| {
        if v != 0 {
            b.push_ones(start, len);
        }
    });
    Ok(b.finish(height, width))
}

/// Encodes a column-major binary mask (pycocotools' native Fortran layout; non-zero = inside).
///
/// # Errors
/// [`RleError::BufferSize`] when `mask.len() != height × width`.
pub fn encode_col_major(mask: &[u8], height: u32, width: u32) -> Result<Rle, RleError> {
    check_len(mask.len(), height, width)?;
    let mut b = RleBuilder::default();
    let mut j = 0;
    while j < mask.len() {
        let v = mask[j] != 0;
        let start = j;
        j += 1;
        while j < mask.len() && (mask[j] != 0) == v {
            j += 1;
        }
        if v {
            b.push_ones(start as u64, (j - start) as u64);
        }
    }
    Ok(b.finish(height, width))
}

/// Encodes every label of a row-major label image at once: entry `k` of the result is the RLE of the
/// mask `labels == k + 1` (0 is background), for `k` in `0..n_labels`.
///
/// This is the connected-component output of [`crate::label::label_components`] turned into one RLE per
/// component in a single pass over the image.
///
/// # Errors
/// [`RleError::BufferSize`] for a buffer of the wrong length, [`RleError::LabelOutOfRange`] for a label
/// above `n_labels`.
pub fn encode_labels(labels: &[u32], height: u32, width: u32, n_labels: usize) -> Result<Vec<Rle>, RleError> {
    check_len(labels.len(), height, width)?;
    let mut builders = vec![RleBuilder::default(); n_labels];
    let mut bad: Option<(u32, u64)> = None;
    for_each_column_run(labels, height as usize, width as usize, |v, start, len| {
        if v == 0 {
            return;
        }
        match builders.get_mut(v as usize - 1) {
            Some(b) => b.push_ones(start, len),
            None => {
                bad.get_or_insert((v, start));
            }
        }
    });
    if let Some((label, start)) = bad {
        let h = height as u64;
        return Err(RleError::LabelOutOfRange {
            label,
            n_labels,
            x: (start / h) as u32,
            y: (start % h) as u32,
        });
    }
    Ok(builders.into_iter().map(|b| b.finish(height, width)).collect())
}

impl Rle {
    /// Builds an RLE from `size = [height, width]` and uncompressed counts (COCO's "uncompressed RLE").
    ///
    /// # Errors
    /// [`RleError::CountSum`] when the counts do not add up to `height × width`.
    pub fn from_counts(size: [u32; 2], counts: Vec<u32>) -> Result<Rle, RleError> {
        let sum: u64 = counts.iter().map(|&c| c as u64).sum();
        let pixels = size[0] as u64 * size[1] as u64;
        if sum != pixels {
            return Err(RleError::CountSum { sum, height: size[0], width: size[1], pixels });
        }
        Ok(Rle { size, counts })
    }

    /// Parses pycocotools' compressed string (`rleFrString`) for an image of `height × width`.
    ///
    /// # Errors
    /// [`RleError::BadChar`] for bytes outside `'0'..='o'`, [`RleError::Truncated`] when the string ends
    /// inside a count, [`RleError::CountOutOfRange`] for counts that are negative or above `u32::MAX`,
    /// [`RleError::CountSum`] when the runs do not cover the image exactly.
    pub fn from_string(s: &str, height: u32, width: u32) -> Result<Rle, RleError> {
        let bytes = s.as_bytes();
        let mut counts: Vec<u32> = Vec::with_capacity(bytes.len());
        let mut p = 0;
        while p < bytes.len() {
            let mut x: i64 = 0;
            let mut k = 0;
            loop {
                let Some(&byte) = bytes.get(p) else {
                    return Err(RleError::Truncated { offset: p });
                };
                if !(48..=111).contains(&byte) {
                    let shown = if byte.is_ascii_graphic() {
                        format!("'{}'", byte as char)
                    } else {
                        "non-printable".to_string()
                    };
                    return Err(RleError::BadChar { offset: p, byte, shown });
                }
                if k >= MAX_GROUPS {
                    return Err(RleError::CountOutOfRange { index: counts.len(), value: x });
                }
                let c = (byte - 48) as i64;
                x |= (c & 0x1f) << (5 * k);
                p += 1;
                k += 1;
                if c & 0x20 == 0 {
                    if c & 0x10 != 0 {
                        x |= -1i64 << (5 * k);
                    }
                    break;
                }
            }
            let m = counts.len();
            if m > 2 {
                x += counts[m - 2] as i64;
            }
            if !(0..=u32::MAX as i64).contains(&x) {
                return Err(RleError::CountOutOfRange { index: m, value: x });
            }
            counts.push(x as u32);
        }
        Rle::from_counts([height, width], counts)
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.size[0]
    }

    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.size[1]
    }

    /// Number of pixels inside the mask (`rleArea`): the sum of the odd-indexed counts.
    pub fn area(&self) -> u64 {
        self.counts.iter().skip(1).step_by(2).map(|&c| c as u64).sum()
    }

    /// The bounding box `[x, y, w, h]` in pixels (`rleToBbox`); `[0, 0, 0, 0]` for an empty mask.
    pub fn to_bbox(&self) -> [f64; 4] {
        let h = self.height() as u64;
        let w = self.width() as u64;
        let m = self.counts.len() / 2 * 2;
        if m == 0 || h == 0 {
            return [0.0; 4];
        }
        let (mut xs, mut ys, mut xe, mut ye) = (w, h, 0u64, 0u64);
        let mut cc: u64 = 0;
        let mut xp = 0u64;
        for j in 0..m {
            cc += self.counts[j] as u64;
            // The first pixel of a run of ones (j even: cc is the index after the zeros) or the last
            // pixel of it (j odd).
            let t = cc - (j % 2) as u64;
            let y = t % h;
            let x = (t - y) / h;
            if j % 2 == 0 {
                xp = x;
            } else if xp < x {
                // The run wraps from one column into the next: it covers the full height.
                ys = 0;
                ye = h - 1;
            }
            xs = xs.min(x);
            xe = xe.max(x);
            ys = ys.min(y);
            ye = ye.max(y);
        }
        [xs as f64, ys as f64, (xe - xs + 1) as f64, (ye - ys + 1) as f64]
    }

    /// Decodes to a column-major mask of 0/1 bytes (`rleDecode`, pycocotools' Fortran order).
    pub fn decode_col_major(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(self.size[0] as usize * self.size[1] as usize);
        let mut v = 0u8;
        for &c in &self.counts {
            out.resize(out.len() + c as usize, v);
            v ^= 1;
        }
        out
    }

    /// Decodes to a row-major mask of 0/1 bytes (`height` rows of `width` bytes).
    pub fn decode(&self) -> Vec<u8> {
        let (h, w) = (self.size[0] as usize, self.size[1] as usize);
        let mut out = vec![0u8; h * w];
        if h == 0 {
            return out;
        }
        let mut pos = 0usize;
        let mut v = false;
        for &c in &self.counts {
            if v {
                let (mut x, mut y) = (pos / h, pos % h);
                for _ in 0..c {
                    // `get_mut` keeps a hand-built RLE whose counts overshoot the image from panicking.
                    if let Some(px) = out.get_mut(y * w + x) {
                        *px = 1;
                    }
                    y += 1;
                    if y == h {
                        y = 0;
                        x += 1;
                    }
                }
            }
            pos += c as usize;
            v = !v;
        }
        out
    }

    /// The union of masks of equal size (`rleMerge` with `intersect = 0`).
    ///
    /// # Errors
    /// [`RleError::MergeSize`] when the sizes differ (pycocotools silently returns a 0×0 RLE),
    /// [`RleError::CountSum`] for an RLE whose counts do not cover its image (pycocotools loops forever).
    pub fn union(rles: &[Rle]) -> Result<Rle, RleError> {
        merge(rles, false)
    }

    /// The intersection of masks of equal size (`rleMerge` with `intersect = 1`).
    ///
    /// # Errors
    /// As [`Rle::union`].
    pub fn intersection(rles: &[Rle]) -> Result<Rle, RleError> {
        merge(rles, true)
    }
}

/// `rleMerge`: union (or intersection) of masks, walking the runs of both operands in step exactly as
/// pycocotools does, so that the counts come out identical even for non-canonical inputs. Zero masks
/// give the 0×0 RLE `[]`, like pycocotools.
///
/// # Errors
/// [`RleError::MergeSize`] when the sizes differ, [`RleError::CountSum`] for an RLE whose counts do not
/// cover its image.
pub fn merge(rles: &[Rle], intersect: bool) -> Result<Rle, RleError> {
    let Some(first) = rles.first() else {
        return Ok(Rle { size: [0, 0], counts: Vec::new() });
    };
    // pycocotools loops forever when one operand's runs end before the other's: check the sums first.
    for r in rles {
        let sum: u64 = r.counts.iter().map(|&c| c as u64).sum();
        let pixels = r.size[0] as u64 * r.size[1] as u64;
        if sum != pixels && !(r.counts.is_empty() && pixels == 0) {
            return Err(RleError::CountSum { sum, height: r.size[0], width: r.size[1], pixels });
        }
    }
    let mut acc = first.counts.clone();
    for b in &rles[1..] {
        if b.size != first.size {
            return Err(RleError::MergeSize { a: first.size, b: b.size });
        }
        if acc.is_empty() || b.counts.is_empty() {
            // pycocotools reads cnts[0] of both operands; an RLE without counts only arises for 0×0.
            acc = Vec::new();
            continue;
        }
        let a = std::mem::take(&mut acc);
        let (mut ca, mut cb) = (a[0], b.counts[0]);
        let (mut va, mut vb, mut v) = (false, false, false);
        let (mut ia, mut ib) = (1usize, 1usize);
        let mut cc: u32 = 0;
        loop {
            let c = ca.min(cb);
            cc += c;
            let mut ct: u64 = 0;
            ca -= c;
            if ca == 0 && ia < a.len() {
                ca = a[ia];
                ia += 1;
                va = !va;
            }
            ct += ca as u64;
            cb -= c;
            if cb == 0 && ib < b.counts.len() {
                cb = b.counts[ib];
                ib += 1;
                vb = !vb;
            }
            ct += cb as u64;
            let vp = v;
            v = if intersect { va && vb } else { va || vb };
            if v != vp || ct == 0 {
                acc.push(cc);
                cc = 0;
            }
            if ct == 0 {
                break;
            }
        }
    }
    Ok(Rle { size: first.size, counts: acc })
}

impl fmt::Display for Rle {
    /// Writes the compressed string (`rleToString`).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut buf = Vec::with_capacity(self.counts.len() * 2);
        write_compressed(&self.counts, &mut buf);
        // Every byte is in 48..=111, so the buffer is ASCII.
        f.write_str(std::str::from_utf8(&buf).map_err(|_| fmt::Error)?)
    }
}

/// Appends the compressed form of `counts` to `out` (pycocotools' `rleToString`).
fn write_compressed(counts: &[u32], out: &mut Vec<u8>) {
    for (i, &count) in counts.iter().enumerate() {
        let mut x = count as i64;
        if i > 2 {
            x -= counts[i - 2] as i64;
        }
        loop {
            let mut c = (x & 0x1f) as u8;
            x >>= 5;
            let more = if c & 0x10 != 0 { x != -1 } else { x != 0 };
            if more {
                c |= 0x20;
            }
            out.push(c + 48);
            if !more {
                break;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Pixel-by-pixel reference: the straightforward `rleEncode` loop over a column-major copy.
    fn reference_encode(mask_rows: &[u8], h: usize, w: usize) -> Vec<u32> {
        let mut col = Vec::with_capacity(h * w);
        for x in 0..w {
            for y in 0..h {
                col.push(mask_rows[y * w + x]);
            }
        }
        let (mut counts, mut p, mut c) = (Vec::new(), 0u8, 0u32);
        for &v in &col {
            if v != p {
                counts.push(c);
                c = 0;
                p = v;
            }
            c += 1;
        }
        counts.push(c);
        counts
    }

    fn random_mask(rng: &mut ChaCha8Rng, h: usize, w: usize, density: f64) -> Vec<u8> {
        (0..h * w).map(|_| rng.gen_bool(density) as u8).collect()
    }

    mod golden {
        use super::*;

        /// The vectors of `../shared/fixtures/coco_rle_golden.json` (computed with pycocotools 2.0)
        /// that are small enough to inline; the full file is checked in `tests/it/coco_rle.rs`.
        #[test]
        fn small_cases_from_pycocotools() {
            let rect = [0, 0, 0, 0, 0, 0, 1, 1, 1, 0, 0, 1, 1, 1, 0, 0, 0, 0, 0, 0];
            let r = encode(&rect, 4, 5).unwrap();
            assert_eq!(r.counts, [5, 2, 2, 2, 2, 2, 5]);
            assert_eq!(r.to_string(), "5220003");
            assert_eq!(r.to_bbox(), [1.0, 1.0, 3.0, 2.0]);
            assert_eq!(r.area(), 6);

            let full = encode(&[1; 9], 3, 3).unwrap();
            assert_eq!((full.counts.as_slice(), full.to_string().as_str()), (&[0, 9][..], "09"));
            let empty = encode(&[0; 9], 3, 3).unwrap();
            assert_eq!((empty.counts.as_slice(), empty.to_string().as_str()), (&[9][..], "9"));
            assert_eq!(empty.to_bbox(), [0.0; 4]);
            let mut first = [0u8; 9];
            first[0] = 1;
            let f = encode(&first, 3, 3).unwrap();
            assert_eq!((f.counts.as_slice(), f.to_string().as_str()), (&[0, 1, 8][..], "018"));

            // lastcols_6x4: the last column full, plus (x=2, y=5); the runs join across the column break.
            let mut lc = [0u8; 24];
            for y in 0..6 {
                lc[y * 4 + 3] = 1;
            }
            lc[5 * 4 + 2] = 1;
            let r = encode(&lc, 6, 4).unwrap();
            assert_eq!(r.counts, [17, 7]);
            assert_eq!(r.to_string(), "a07");
            assert_eq!(r.to_bbox(), [2.0, 0.0, 2.0, 6.0]);
        }
    }

    mod encode {
        use super::*;

        #[test]
        fn matches_reference_loop_on_random_masks() {
            let mut rng = ChaCha8Rng::seed_from_u64(7);
            for &(h, w) in &[(1, 1), (1, 17), (17, 1), (3, 70), (70, 3), (33, 65), (64, 64)] {
                for &d in &[0.0, 0.05, 0.5, 0.95, 1.0] {
                    let m = random_mask(&mut rng, h, w, d);
                    let r = encode(&m, h as u32, w as u32).unwrap();
                    assert_eq!(r.counts, reference_encode(&m, h, w), "{h}×{w} density {d}");
                    assert_eq!(r.area(), m.iter().map(|&v| v as u64).sum::<u64>());
                    assert_eq!(r.decode(), m);
                    let mut col = vec![0u8; h * w];
                    for y in 0..h {
                        for x in 0..w {
                            col[x * h + y] = m[y * w + x];
                        }
                    }
                    assert_eq!(encode_col_major(&col, h as u32, w as u32).unwrap(), r);
                    assert_eq!(r.decode_col_major(), col);
                }
            }
        }

        #[test]
        fn any_non_zero_byte_is_inside() {
            let mut rng = ChaCha8Rng::seed_from_u64(17);
            let (h, w) = (19, 23);
            let m: Vec<u8> = (0..h * w).map(|_| [0, 0, 1, 2, 255][rng.gen_range(0..5)]).collect();
            let binary: Vec<u8> = m.iter().map(|&v| (v != 0) as u8).collect();
            assert_eq!(encode(&m, h as u32, w as u32).unwrap().counts, reference_encode(&binary, h, w));
        }

        #[test]
        fn zero_sized_image_is_a_single_zero_count() {
            assert_eq!(encode(&[], 0, 5).unwrap().counts, [0]);
            assert_eq!(encode(&[], 4, 0).unwrap().to_string(), "0");
        }

        #[test]
        fn wrong_buffer_length_is_an_error() {
            assert_eq!(encode(&[0; 5], 2, 3), Err(RleError::BufferSize { len: 5, height: 2, width: 3 }));
        }

        #[test]
        fn labels_at_once_equal_masks_one_by_one() {
            let mut rng = ChaCha8Rng::seed_from_u64(11);
            for &(h, w) in &[(1, 40), (40, 1), (37, 53), (50, 100)] {
                let n = 6usize;
                let labels: Vec<u32> = (0..h * w).map(|_| rng.gen_range(0..=n as u32)).collect();
                let rles = encode_labels(&labels, h as u32, w as u32, n).unwrap();
                assert_eq!(rles.len(), n);
                for (k, r) in rles.iter().enumerate() {
                    let m: Vec<u8> = labels.iter().map(|&l| (l == k as u32 + 1) as u8).collect();
                    assert_eq!(r.counts, reference_encode(&m, h, w), "label {} of {h}×{w}", k + 1);
                }
            }
        }

        #[test]
        fn label_above_count_is_reported_with_its_pixel() {
            let labels = [0, 1, 0, 0, 0, 3];
            let err = encode_labels(&labels, 2, 3, 2).unwrap_err();
            assert_eq!(err, RleError::LabelOutOfRange { label: 3, n_labels: 2, x: 2, y: 1 });
        }
    }

    mod string {
        use super::*;

        #[test]
        fn round_trips_large_and_alternating_counts() {
            // Large counts need several groups; differences (i > 2) go negative.
            let counts = vec![3_000_000, 1, 2_999_000, 70_000, 5, 1_000_000, 17, 0, 64, 32, 31, 16];
            let sum: u64 = counts.iter().map(|&c| c as u64).sum();
            let r = Rle::from_counts([1, sum as u32], counts).unwrap();
            let s = r.to_string();
            assert!(s.bytes().all(|b| (48..=111).contains(&b)));
            assert_eq!(Rle::from_string(&s, 1, sum as u32).unwrap(), r);
        }

        #[test]
        fn hand_computed_encoding_of_a_negative_difference() {
            // counts [1, 2, 3, 1]: 1→'1', 2→'2', 3→'3', 1−2 = −1 → group 0x1f with no more → 31+48 = 'O'.
            let r = Rle::from_counts([7, 1], vec![1, 2, 3, 1]).unwrap();
            assert_eq!(r.to_string(), "123O");
            // 40 = 0b01000_01000 → groups 8 (more: 8|0x20 = 40 → 'X') then 1 → "X1".
            assert_eq!(Rle::from_counts([40, 1], vec![40]).unwrap().to_string(), "X1");
        }

        #[test]
        fn rejects_bad_bytes_truncation_and_wrong_sums() {
            assert!(matches!(Rle::from_string("12z", 1, 3), Err(RleError::BadChar { offset: 2, .. })));
            assert!(matches!(Rle::from_string("X", 40, 1), Err(RleError::Truncated { offset: 1 })));
            assert!(matches!(Rle::from_string("12", 1, 4), Err(RleError::CountSum { sum: 3, .. })));
            assert!(matches!(
                Rle::from_string("0000000", 1, 1),
                Err(RleError::CountOutOfRange { .. }) | Err(RleError::CountSum { .. })
            ));
            assert!(matches!(Rle::from_string("XXXXXXXX1", 1, 1), Err(RleError::CountOutOfRange { .. })));
            // A first count of −1 ('O').
            assert!(matches!(Rle::from_string("O", 1, 1), Err(RleError::CountOutOfRange { index: 0, .. })));
        }
    }

    mod bbox {
        use super::*;

        /// Reference bounding box from the row-major mask itself.
        fn reference_bbox(m: &[u8], h: usize, w: usize) -> [f64; 4] {
            let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
            for y in 0..h {
                for x in 0..w {
                    if m[y * w + x] != 0 {
                        (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
                    }
                }
            }
            if x0 == usize::MAX {
                return [0.0; 4];
            }
            [x0 as f64, y0 as f64, (x1 - x0 + 1) as f64, (y1 - y0 + 1) as f64]
        }

        #[test]
        fn equals_the_tight_box_of_the_pixels() {
            let mut rng = ChaCha8Rng::seed_from_u64(3);
            for &(h, w) in &[(1, 9), (9, 1), (5, 5), (20, 31)] {
                for &d in &[0.0, 0.02, 0.2, 0.9, 1.0] {
                    let m = random_mask(&mut rng, h, w, d);
                    let r = encode(&m, h as u32, w as u32).unwrap();
                    assert_eq!(r.to_bbox(), reference_bbox(&m, h, w), "{h}×{w} {d}");
                }
            }
        }
    }

    mod merge {
        use super::*;

        #[test]
        fn union_and_intersection_equal_pixelwise_or_and() {
            let mut rng = ChaCha8Rng::seed_from_u64(5);
            let (h, w) = (23, 31);
            for _ in 0..20 {
                let ms: Vec<Vec<u8>> = (0..3).map(|_| random_mask(&mut rng, h, w, 0.3)).collect();
                let rles: Vec<Rle> = ms.iter().map(|m| encode(m, h as u32, w as u32).unwrap()).collect();
                let or: Vec<u8> = (0..h * w).map(|i| ms.iter().any(|m| m[i] != 0) as u8).collect();
                let and: Vec<u8> = (0..h * w).map(|i| ms.iter().all(|m| m[i] != 0) as u8).collect();
                assert_eq!(Rle::union(&rles).unwrap(), encode(&or, h as u32, w as u32).unwrap());
                assert_eq!(Rle::intersection(&rles).unwrap(), encode(&and, h as u32, w as u32).unwrap());
            }
        }

        #[test]
        fn single_and_empty_inputs() {
            let r = encode(&[0, 1, 1, 0], 2, 2).unwrap();
            assert_eq!(Rle::union(std::slice::from_ref(&r)).unwrap(), r);
            assert_eq!(Rle::union(&[]).unwrap(), Rle { size: [0, 0], counts: vec![] });
            let broken = Rle { size: [2, 2], counts: vec![1, 1] };
            assert!(matches!(Rle::union(&[r.clone(), broken]), Err(RleError::CountSum { sum: 2, .. })));
            let other = encode(&[0; 6], 2, 3).unwrap();
            assert!(matches!(Rle::union(&[r, other]), Err(RleError::MergeSize { .. })));
        }
    }
}
