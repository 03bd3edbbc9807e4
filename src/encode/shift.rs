//! The shear's shift kernels: one pass over the depth rows of a sheared mask
//! moves every slice's bits by −1, 0 or +1 (one step; three shift vectors) or
//! by −2..=+2 (two fused steps; five vectors).
//!
//! Each kernel is compiled for the column lengths it is called with (`N`
//! words per depth row, 1 to [`crate::encode::mask::MAX_FIXED_COLUMN`]). For
//! longer columns (4-bit preset codes on 512 slices: 32 words) the one-pass
//! move along j and the single step along j build each column a chunk of
//! `column_chunk` words at a time (`*_chunks`); the other kernels keep a
//! general loop. Every fixed-length and chunked kernel has an AVX2 copy (`*_avx2`, `#[target_feature(enable = "avx2")]`) whose body
//! is the plain one: [`crate::encode::mask::BinaryMask`] picks between them by
//! its [`crate::kernels::CpuLevel`], and the invariant tests compare every
//! level with the scalar kernels word for word.

use crate::encode::depth::{Word, slot_mask};

/// One grid row of [`BinaryMask::shift_columns`] for columns of `N` words:
/// columns `ps..=pe` of `row` become `old[p] & keep | old[p−1] & up | old[p+1] & down`
/// (the column before `ps` is read as it is, the one past the row's end as zero).
#[inline(always)]
pub(crate) fn shift_columns_n<W: Word, const N: usize>(row: &mut [W], ps: usize, pe: usize, up: &[W], down: &[W], keep: &[W]) {
    let (up, down, keep): (&[W; N], &[W; N], &[W; N]) = (fixed(up), fixed(down), fixed(keep));
    let (cols, _) = row.as_chunks_mut::<N>();
    let gw = cols.len();
    let mix = |prev: &[W; N], old: &[W; N], next: &[W; N]| -> [W; N] {
        std::array::from_fn(|w| (old[w] & keep[w]) | (prev[w] & up[w]) | (next[w] & down[w]))
    };
    let mut prev = if ps > 0 { cols[ps - 1] } else { [W::ZERO; N] };
    let mut old = cols[ps];
    let mut p = ps;
    // four columns a block while the block's last read (p + 4) is in the
    // row: the window lives in named values, so no copies between columns,
    // and one test bounds the block's reads and writes
    while p + 3 <= pe && p + 4 < gw {
        let c = &mut cols[p..p + 5];
        let (n1, n2, n3, n4) = (c[1], c[2], c[3], c[4]);
        c[0] = mix(&prev, &old, &n1);
        c[1] = mix(&old, &n1, &n2);
        c[2] = mix(&n1, &n2, &n3);
        c[3] = mix(&n2, &n3, &n4);
        (prev, old) = (n3, n4);
        p += 4;
    }
    while p <= pe {
        let next = if p + 1 < gw { cols[p + 1] } else { [W::ZERO; N] };
        cols[p] = mix(&prev, &old, &next);
        prev = old;
        old = next;
        p += 1;
    }
}

/// The first `N` words of `s` as an array (the caller guarantees the length).
#[inline(always)]
pub(crate) fn fixed<W: Word, const N: usize>(s: &[W]) -> &[W; N] {
    s[..N].try_into().expect("N words")
}

/// [`shift_columns_n`] for any column length `nw`, in blocks of 64 words per
/// column so that the previous column's old words ride in a stack buffer.
pub(crate) fn shift_columns_any<W: Word>(row: &mut [W], nw: usize, ps: usize, pe: usize, up: &[W], down: &[W], keep: &[W]) {
    const BUF: usize = 64;
    let gw = row.len() / nw;
    for w0 in (0..nw).step_by(BUF) {
        let m = BUF.min(nw - w0);
        let mut prev = [W::ZERO; BUF];
        if ps > 0 {
            prev[..m].copy_from_slice(&row[(ps - 1) * nw + w0..(ps - 1) * nw + w0 + m]);
        }
        for p in ps..=pe {
            let base = p * nw + w0;
            for w in 0..m {
                let old = row[base + w];
                let nx = if p + 1 < gw { row[base + nw + w] } else { W::ZERO };
                row[base + w] = (old & keep[w0 + w]) | (prev[w] & up[w0 + w]) | (nx & down[w0 + w]);
                prev[w] = old;
            }
        }
    }
}

/// One grid row of [`BinaryMask::shift_rows`] for columns of `N` words: `row`
/// becomes `row & keep | prev & up | next & down` column by column, and `prev`
/// takes the row's old words (`next` empty: the row below is all zero).
#[inline(always)]
pub(crate) fn shift_row_n<W: Word, const N: usize>(row: &mut [W], next: &[W], prev: &mut [W], up: &[W], down: &[W], keep: &[W]) {
    let (up, down, keep): (&[W; N], &[W; N], &[W; N]) = (fixed(up), fixed(down), fixed(keep));
    let (row, _) = row.as_chunks_mut::<N>();
    let (prev, _) = prev.as_chunks_mut::<N>();
    let (next, _) = next.as_chunks::<N>();
    let column = |cw: &mut [W; N], pw: &mut [W; N], nx: &[W; N]| {
        for w in 0..N {
            let old = cw[w];
            cw[w] = (old & keep[w]) | (pw[w] & up[w]) | (nx[w] & down[w]);
            pw[w] = old;
        }
    };
    if next.is_empty() {
        // past the grid's last row: the row below reads as zero
        row.iter_mut().zip(prev.iter_mut()).for_each(|(cw, pw)| column(cw, pw, &[W::ZERO; N]));
    } else {
        row.iter_mut().zip(prev.iter_mut()).zip(next).for_each(|((cw, pw), nx)| column(cw, pw, nx));
    }
}

/// One grid row of [`BinaryMask::shift_columns2`] for columns of `N` words:
/// columns `ps..=pe` become `OR_j old[p − 2 + j] & m[j]` (columns before `ps`
/// are read as they are, those past the row's end as zero). The five old
/// columns around `p` ride in a window, so a column is written after it is read.
#[inline(always)]
pub(crate) fn shift_columns2_n<W: Word, const N: usize>(row: &mut [W], ps: usize, pe: usize, m: [&[W; N]; 5]) {
    let (cols, _) = row.as_chunks_mut::<N>();
    let gw = cols.len();
    let col = |cols: &[[W; N]], p: usize| if p < gw { cols[p] } else { [W::ZERO; N] };
    let mix = |a: &[W; N], b: &[W; N], c: &[W; N], d: &[W; N], e: &[W; N]| -> [W; N] {
        std::array::from_fn(|w| (a[w] & m[0][w]) | (b[w] & m[1][w]) | (c[w] & m[2][w]) | (d[w] & m[3][w]) | (e[w] & m[4][w]))
    };
    // ps − 2 and ps − 1 wrap to huge indices (read as zero) at the grid's edge
    let (mut a, mut b, mut c, mut d, mut e) =
        (col(cols, ps.wrapping_sub(2)), col(cols, ps.wrapping_sub(1)), col(cols, ps), col(cols, ps + 1), col(cols, ps + 2));
    let mut p = ps;
    // four columns a block while the block's last read (p + 6) is in the
    // row: the window lives in named values (no copies between columns), a
    // column is read (three ahead) before it is written, and one test bounds
    // the block
    while p + 3 <= pe && p + 6 < gw {
        let s = &mut cols[p..p + 7];
        let f = s[3];
        s[0] = mix(&a, &b, &c, &d, &e);
        let g = s[4];
        s[1] = mix(&b, &c, &d, &e, &f);
        let h = s[5];
        s[2] = mix(&c, &d, &e, &f, &g);
        let i = s[6];
        s[3] = mix(&d, &e, &f, &g, &h);
        (a, b, c, d, e) = (e, f, g, h, i);
        p += 4;
    }
    while p <= pe {
        let f = col(cols, p + 3);
        cols[p] = mix(&a, &b, &c, &d, &e);
        (a, b, c, d, e) = (b, c, d, e, f);
        p += 1;
    }
}

/// One grid row of [`BinaryMask::shift_rows2`] for columns of `N` words: `row`
/// becomes `prev2 & m[0] | prev1 & m[1] | row & m[2] | next1 & m[3] | next2 & m[4]`
/// column by column; `prev2` takes `prev1` and `prev1` the row's old words.
#[inline(always)]
pub(crate) fn shift_row2_n<W: Word, const N: usize>(
    row: &mut [W],
    next1: &[W],
    next2: &[W],
    prev1: &mut [W],
    prev2: &mut [W],
    m: [&[W; N]; 5],
) {
    let (row, _) = row.as_chunks_mut::<N>();
    let (prev1, _) = prev1.as_chunks_mut::<N>();
    let (prev2, _) = prev2.as_chunks_mut::<N>();
    let (next1, _) = next1.as_chunks::<N>();
    let (next2, _) = next2.as_chunks::<N>();
    for ((((cw, p1), p2), n1), n2) in row.iter_mut().zip(prev1.iter_mut()).zip(prev2.iter_mut()).zip(next1).zip(next2) {
        for w in 0..N {
            let old = cw[w];
            cw[w] = (p2[w] & m[0][w]) | (p1[w] & m[1][w]) | (old & m[2][w]) | (n1[w] & m[3][w]) | (n2[w] & m[4][w]);
            p2[w] = p1[w];
            p1[w] = old;
        }
    }
}

/// A source of [`move_row_n`]: an old row (its columns of `N` words) and,
/// per word, the slots taken from it.
pub(crate) type MoveSource<'a, W, const N: usize> = (&'a [[W; N]], &'a [W; N]);

/// One grid row of [`BinaryMask::move_rows`](crate::encode::mask::BinaryMask)
/// for columns of `N` words: word `w` of column `c` becomes
/// `OR_s src_s[c][w] & slots_s[w]` over the sources (each old row the row's
/// slots move from, with the slots moving from it), so each column is built
/// in registers and written once.
#[inline(always)]
pub(crate) fn move_row_n<W: Word, const N: usize>(row: &mut [[W; N]], srcs: &[MoveSource<W, N>]) {
    for (c, out) in row.iter_mut().enumerate() {
        let mut acc = [W::ZERO; N];
        for &(src, slots) in srcs {
            let s = &src[c];
            for w in 0..N {
                acc[w] |= s[w] & slots[w];
            }
        }
        *out = acc;
    }
}

/// The chunk, in words, in which the `_chunks` kernels build a column of `nw`
/// words, for columns longer than the fixed lengths (1 to 16): the largest of
/// 16, 8, 4, 2 and 1 that divides `nw`.
pub(crate) fn column_chunk(nw: usize) -> usize {
    [16, 8, 4, 2].into_iter().find(|c| nw.is_multiple_of(*c)).unwrap_or(1)
}

/// A source of [`move_row_chunks`]: an old row and, per word of a column,
/// the slots taken from it.
pub(crate) type MoveSourceAny<'a, W> = (&'a [W], &'a [W]);

/// [`move_row_n`] for columns of any length `nw`, a multiple of `C`
/// ([`column_chunk`]): each column built in chunks of `C` words, each chunk
/// in registers from every source and written once.
#[inline(always)]
pub(crate) fn move_row_chunks<W: Word, const C: usize>(row: &mut [W], nw: usize, srcs: &[MoveSourceAny<W>]) {
    debug_assert!(nw.is_multiple_of(C));
    for (c, column) in row.chunks_exact_mut(nw).enumerate() {
        for (h, out) in column.as_chunks_mut::<C>().0.iter_mut().enumerate() {
            let (at, w0) = (c * nw + h * C, h * C);
            let mut acc = [W::ZERO; C];
            for &(src, slots) in srcs {
                let (s, m): (&[W; C], &[W; C]) = (fixed(&src[at..]), fixed(&slots[w0..]));
                for w in 0..C {
                    acc[w] |= s[w] & m[w];
                }
            }
            *out = acc;
        }
    }
}

/// [`move_row_chunks`] compiled for AVX2. Callers must hold a [`CpuLevel`]
/// with AVX2 that is at most [`kernels::detected`].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
pub(crate) unsafe fn move_row_chunks_avx2<W: Word, const C: usize>(row: &mut [W], nw: usize, srcs: &[MoveSourceAny<W>]) {
    move_row_chunks::<W, C>(row, nw, srcs)
}

/// [`shift_row_n`] for columns of any length `nw`, a multiple of `C`
/// ([`column_chunk`]), a chunk of `C` words at a time.
#[inline(always)]
pub(crate) fn shift_row_chunks<W: Word, const C: usize>(row: &mut [W], next: &[W], prev: &mut [W], nw: usize, [up, down, keep]: [&[W]; 3]) {
    debug_assert!(nw.is_multiple_of(C));
    let zero = [W::ZERO; C];
    for (c, (cw, pw)) in row.chunks_exact_mut(nw).zip(prev.chunks_exact_mut(nw)).enumerate() {
        let (cw, pw) = (cw.as_chunks_mut::<C>().0, pw.as_chunks_mut::<C>().0);
        for (h, (cw, pw)) in cw.iter_mut().zip(pw.iter_mut()).enumerate() {
            let w0 = h * C;
            // past the grid's last row: the row below reads as zero
            let nx: &[W; C] = if next.is_empty() { &zero } else { fixed(&next[c * nw + w0..]) };
            let (u, d, k): (&[W; C], &[W; C], &[W; C]) = (fixed(&up[w0..]), fixed(&down[w0..]), fixed(&keep[w0..]));
            for w in 0..C {
                let old = cw[w];
                cw[w] = (old & k[w]) | (pw[w] & u[w]) | (nx[w] & d[w]);
                pw[w] = old;
            }
        }
    }
}

/// [`shift_row_chunks`] compiled for AVX2. Callers must hold a
/// [`CpuLevel`] with AVX2 that is at most [`kernels::detected`].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
pub(crate) unsafe fn shift_row_chunks_avx2<W: Word, const C: usize>(
    row: &mut [W],
    next: &[W],
    prev: &mut [W],
    nw: usize,
    masks: [&[W]; 3],
) {
    shift_row_chunks::<W, C>(row, next, prev, nw, masks)
}

/// [`move_row_n`] compiled for AVX2. Callers must hold a [`CpuLevel`] with
/// AVX2 that is at most [`kernels::detected`].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
pub(crate) unsafe fn move_row_n_avx2<W: Word, const N: usize>(row: &mut [[W; N]], srcs: &[MoveSource<W, N>]) {
    move_row_n::<W, N>(row, srcs)
}

/// [`shift_columns2_n`] compiled for AVX2. Callers must hold a [`CpuLevel`]
/// with AVX2 that is at most [`kernels::detected`].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
pub(crate) unsafe fn shift_columns2_n_avx2<W: Word, const N: usize>(row: &mut [W], ps: usize, pe: usize, m: [&[W; N]; 5]) {
    shift_columns2_n::<W, N>(row, ps, pe, m)
}

/// [`shift_row2_n`] compiled for AVX2. Callers must hold a [`CpuLevel`]
/// with AVX2 that is at most [`kernels::detected`].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
pub(crate) unsafe fn shift_row2_n_avx2<W: Word, const N: usize>(
    row: &mut [W],
    next1: &[W],
    next2: &[W],
    prev1: &mut [W],
    prev2: &mut [W],
    m: [&[W; N]; 5],
) {
    shift_row2_n::<W, N>(row, next1, next2, prev1, prev2, m)
}

/// [`shift_columns_n`] compiled for AVX2: a column of up to four u64 words is
/// one 256-bit register. Callers must hold a [`CpuLevel`]
/// with AVX2 that is at most [`kernels::detected`].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
pub(crate) unsafe fn shift_columns_n_avx2<W: Word, const N: usize>(row: &mut [W], ps: usize, pe: usize, up: &[W], down: &[W], keep: &[W]) {
    shift_columns_n::<W, N>(row, ps, pe, up, down, keep)
}

/// [`shift_row_n`] compiled for AVX2. Callers must hold a [`CpuLevel`]
/// with AVX2 that is at most [`kernels::detected`].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
pub(crate) unsafe fn shift_row_n_avx2<W: Word, const N: usize>(
    row: &mut [W],
    next: &[W],
    prev: &mut [W],
    up: &[W],
    down: &[W],
    keep: &[W],
) {
    shift_row_n::<W, N>(row, next, prev, up, down, keep)
}

/// Per-word shift vectors for one step along one axis, for rows of `nb`-bit
/// codes: every bit of slice `k`'s slot is set in `up` when the slice moves one
/// position up (towards higher mask index), in `down` when it moves one down, so
/// the bits of a code always move together. `from`/`to` are the slices' current
/// and target mask offsets.
///
/// Returns the largest `|to − from|` seen; the vectors are only meaningful when
/// that is at most 1.
pub fn shift_vectors<W: Word>(nb: u32, from: &[i32], to: &[i32], up: &mut [W], down: &mut [W]) -> u32 {
    up.fill(W::ZERO);
    down.fill(W::ZERO);
    let mut worst = 0u32;
    let slots = (W::BITS / nb) as usize;
    for (k, (&a, &b)) in from.iter().zip(to).enumerate() {
        let d = b - a;
        worst = worst.max(d.unsigned_abs());
        let w = k / slots;
        let bit = slot_mask::<W>(nb, k);
        if d > 0 {
            up[w] |= bit;
        } else if d < 0 {
            down[w] |= bit;
        }
    }
    worst
}

/// The shift vectors of two fused steps from offsets `from` to `to` (every
/// slice moving by d ∈ −2..=2): `moves[2 − d]` holds the slots of the slices
/// that move by d, `moves[2]` (no move) every other slot of the words, so the
/// five are disjoint and cover every bit. Returns the largest |d|.
pub fn shift_vectors2<W: Word>(nb: u32, from: &[i32], to: &[i32], moves: &mut [Vec<W>; 5]) -> u32 {
    for m in moves.iter_mut() {
        m.fill(W::ZERO);
    }
    let mut worst = 0u32;
    let slots = (W::BITS / nb) as usize;
    for (k, (&a, &b)) in from.iter().zip(to).enumerate() {
        let d = b - a;
        debug_assert!(d.abs() <= 2, "a fused step moves at most two bits");
        worst = worst.max(d.unsigned_abs());
        if d != 0 {
            moves[(2 - d) as usize][k / slots] |= slot_mask::<W>(nb, k);
        }
    }
    let [m0, m1, keep, m3, m4] = moves;
    for (w, k) in keep.iter_mut().enumerate() {
        *k = !(m0[w] | m1[w] | m3[w] | m4[w]);
    }
    worst
}

/// One grid row of a staged shear ([`BinaryMask`](crate::encode::mask::BinaryMask)'s
/// far moves): the slots of `mv` move `t` columns towards larger `p` (`up`) or
/// smaller, in place, over columns `ps..=pe` of `row` (columns of `nw` words);
/// a slot's source past the row's ends reads as zero. Up runs from the last
/// column down and down from the first up, so every source is read before it
/// is written.
pub(crate) fn move_columns<W: Word>(row: &mut [W], nw: usize, ps: usize, pe: usize, t: usize, mv: &[W], up: bool) {
    let gw = row.len() / nw;
    let mut column = |p: usize, src: Option<usize>| {
        for w in 0..nw {
            let from = src.map_or(W::ZERO, |s| row[s * nw + w]);
            let at = &mut row[p * nw + w];
            *at = (*at & !mv[w]) | (from & mv[w]);
        }
    };
    if up {
        for p in (ps..=pe).rev() {
            column(p, p.checked_sub(t));
        }
    } else {
        for p in ps..=pe {
            column(p, Some(p + t).filter(|&s| s < gw));
        }
    }
}

/// [`move_columns`] for columns of `N` words: the columns whose source lies
/// in the row run without a test, a column's words combined in registers.
#[inline(always)]
pub(crate) fn move_columns_n<W: Word, const N: usize>(row: &mut [W], ps: usize, pe: usize, t: usize, mv: &[W], up: bool) {
    let mv: &[W; N] = fixed(mv);
    let (cols, _) = row.as_chunks_mut::<N>();
    let gw = cols.len();
    let blend = |at: &mut [W; N], from: [W; N]| {
        for w in 0..N {
            at[w] = (at[w] & !mv[w]) | (from[w] & mv[w]);
        }
    };
    if up {
        // columns split..=pe read column p − t; those below t read zero
        let split = t.clamp(ps, pe + 1);
        for p in (split..=pe).rev() {
            let from = cols[p - t];
            blend(&mut cols[p], from);
        }
        for at in &mut cols[ps..split] {
            blend(at, [W::ZERO; N]);
        }
    } else {
        // columns ps..split read column p + t (inside the row); the rest zero
        let split = (gw - t.min(gw)).clamp(ps, pe + 1);
        for p in ps..split {
            let from = cols[p + t];
            blend(&mut cols[p], from);
        }
        for at in &mut cols[split..=pe] {
            blend(at, [W::ZERO; N]);
        }
    }
}

/// [`move_columns_n`] compiled for AVX2. Callers must hold a [`CpuLevel`]
/// with AVX2 that is at most [`kernels::detected`].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
pub(crate) unsafe fn move_columns_n_avx2<W: Word, const N: usize>(row: &mut [W], ps: usize, pe: usize, t: usize, mv: &[W], up: bool) {
    move_columns_n::<W, N>(row, ps, pe, t, mv, up)
}

/// One pass of [`move_rows`]: the grid rows are `row_len` words long; rows
/// `qs[0]..=qs[1]`, words `span` of each, take their slots from the row `t`
/// before them (`up`: towards larger `q`) or after.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RowMove {
    pub row_len: usize,
    pub span: [usize; 2],
    pub qs: [usize; 2],
    pub t: usize,
    pub up: bool,
}

/// [`move_columns`] along `j`: the slots of `mv` move as `m` says, in place.
pub(crate) fn move_rows<W: Word>(words: &mut [W], m: RowMove, mv: &[W]) {
    let nw = mv.len();
    move_rows_by(words, m, |dst: &mut [W], src: Option<&[W]>| match src {
        Some(src) => {
            for (d, s) in dst.chunks_exact_mut(nw).zip(src.chunks_exact(nw)) {
                for w in 0..nw {
                    d[w] = (d[w] & !mv[w]) | (s[w] & mv[w]);
                }
            }
        }
        None => {
            for d in dst.chunks_exact_mut(nw) {
                for w in 0..nw {
                    d[w] &= !mv[w];
                }
            }
        }
    })
}

/// [`move_rows`] for columns of `N` words: a column's words blended in
/// registers.
#[inline(always)]
pub(crate) fn move_rows_n<W: Word, const N: usize>(words: &mut [W], m: RowMove, mv: &[W]) {
    let mv: &[W; N] = fixed(mv);
    move_rows_by(words, m, |dst: &mut [W], src: Option<&[W]>| {
        let (dst, _) = dst.as_chunks_mut::<N>();
        match src {
            Some(src) => {
                for (d, s) in dst.iter_mut().zip(src.as_chunks::<N>().0) {
                    for w in 0..N {
                        d[w] = (d[w] & !mv[w]) | (s[w] & mv[w]);
                    }
                }
            }
            None => {
                for d in dst {
                    for w in 0..N {
                        d[w] &= !mv[w];
                    }
                }
            }
        }
    })
}

/// [`move_rows_n`] compiled for AVX2. Callers must hold a [`CpuLevel`]
/// with AVX2 that is at most [`kernels::detected`].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
pub(crate) unsafe fn move_rows_n_avx2<W: Word, const N: usize>(words: &mut [W], m: RowMove, mv: &[W]) {
    move_rows_n::<W, N>(words, m, mv)
}

/// The row order and sources of [`move_rows`]: `blend(dst, src)` takes each
/// row's words `span` and its source row's (`None` past the grid's ends).
#[inline(always)]
fn move_rows_by<W: Word>(words: &mut [W], m: RowMove, blend: impl Fn(&mut [W], Option<&[W]>)) {
    let RowMove { row_len, span, qs: [q0, q1], t, up } = m;
    let rows = words.len() / row_len;
    for i in 0..=q1 - q0 {
        let q = if up { q1 - i } else { q0 + i };
        let src = if up { q.checked_sub(t) } else { Some(q + t).filter(|&s| s < rows) };
        let (dst, src) = match src {
            None => (&mut words[q * row_len + span[0]..q * row_len + span[1]], None),
            Some(s) if s < q => {
                let (head, tail) = words.split_at_mut(q * row_len);
                (&mut tail[span[0]..span[1]], Some(&head[s * row_len + span[0]..s * row_len + span[1]]))
            }
            Some(s) => {
                let (head, tail) = words.split_at_mut(s * row_len);
                (&mut head[q * row_len + span[0]..q * row_len + span[1]], Some(&tail[span[0]..span[1]]))
            }
        };
        blend(dst, src);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fused_shift_vectors_are_disjoint_and_cover_every_bit() {
        let from = vec![0, 0, 0, 1, 1, 1, 2, 5];
        let to = vec![-2, 0, 1, 1, 3, 0, 2, 4];
        let mut m: [Vec<u32>; 5] = std::array::from_fn(|_| vec![0u32; 1]);
        assert_eq!(shift_vectors2(1, &from, &to, &mut m), 2);
        // bit 31 − k for slice k
        assert_eq!(m[0][0], 1 << 27, "+2: slice 4");
        assert_eq!(m[1][0], 1 << 29, "+1: slice 2");
        assert_eq!(m[3][0], (1 << 26) | (1 << 24), "−1: slices 5 and 7");
        assert_eq!(m[4][0], 1 << 31, "−2: slice 0");
        assert_eq!(m[2][0], !((1 << 27) | (1 << 29) | (1 << 26) | (1 << 24) | (1 << 31)));
        // 2-bit codes: both bits of a slot move together
        shift_vectors2(2, &from, &to, &mut m);
        assert_eq!(m[0][0], 0b11 << 22);
        assert_eq!(m[4][0], 0b11 << 30);
        assert_eq!(m.iter().fold(0u32, |a, v| a ^ v[0]), u32::MAX, "disjoint and covering");
    }

    #[test]
    fn shift_vectors_split_per_bit() {
        let from = vec![0, 0, 0, 1, 1, 1, 2];
        let to = vec![-1, 0, 1, 1, 2, 0, 2];
        let mut up = vec![0u32; 1];
        let mut down = vec![0u32; 1];
        assert_eq!(shift_vectors(1, &from, &to, &mut up, &mut down), 1);
        assert_eq!(up[0], (1 << 29) | (1 << 27));
        assert_eq!(down[0], (1 << 31) | (1 << 26));
        // 2-bit codes: both bits of a slot move together
        assert_eq!(shift_vectors(2, &from, &to, &mut up, &mut down), 1);
        assert_eq!(up[0], (0b11 << 26) | (0b11 << 22));
        assert_eq!(down[0], (0b11 << 30) | (0b11 << 20));
    }
}
