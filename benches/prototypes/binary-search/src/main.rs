#![allow(unsafe_op_in_unsafe_fn)]
//! A stand-alone measurement prototype (not the product, not built by CI):
//! the binary iso frame's ray search, organised eight ways, over the z-axis
//! frames (0°–45° about y) of a `.den` volume at iso 52, every variant checked
//! against the plain per-ray search bit for bit. It asks where the floor of
//! the search lies on the host, whatever the organisation: per ray with and
//! without the next-row prefetch, 8-bit densities in a plane of their own,
//! strips of rays, two passes a row, several rays in flight with branch-free
//! retire and refill, 8-lane AVX-512 packets (gathers); and the whole render
//! (search plus the hit: refinement against the slice before, eight normal
//! codes through a 128 KB shade table, colour and depth stored). Cells are
//! 3 bytes, as the crate's: the density and a 14-bit code of the central
//! difference gradient's direction (octahedral, 128 × 128).
//!
//! The frames: ray (p, q) samples slice k bilinearly at (p, q) − pad +
//! (k·tan θ + 0.37, 0.21), the mask holds a cell when the largest of its
//! four corners reaches the iso value (exact per ray: a ray at integer
//! (p, q) lies in one cell of each slice), u64 words, at most 256 slices.
//! See benches/README.md for how to run it and what it measured.
//!
//! Measurement code: its unchecked reads rely on the frames it builds itself
//! (a mask bit only where the cell lies in the volume, 256 bytes of slack
//! after the voxels for the gathers' 4-byte loads), and every variant's
//! output is compared with the plain search's on every frame.
use std::arch::x86_64::*;
use std::time::Instant;

const NW: usize = 4; // u64 words per depth row (256 slices)

struct Vol {
    n: [usize; 3],
    vox: Vec<u8>, // 3 bytes a voxel: density, code lo, code hi
    cellmax: Vec<u8>,
    den: Vec<u8>,
    code: Vec<u16>,
}

struct Frame {
    w: usize,
    h: usize,
    base: Vec<i64>,
    wts: Vec<u64>, // wi | wj << 32 (f32 bits)
    wi: Vec<f32>,
    wj: Vec<f32>,
    mask: Vec<u64>,
}

fn load(path: &str) -> Vol {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{path}: {e}"));
    assert!(bytes.len() > 62 && bytes[0..2] == [1, 0], "{path}: not a little-endian VolPack .den file");
    let short = |i: usize| i16::from_le_bytes([bytes[i], bytes[i + 1]]) as usize;
    let n = [short(50), short(52), short(54)];
    let d = &bytes[62..];
    assert_eq!(d.len(), n[0] * n[1] * n[2], "{path}: the header's dimensions {n:?} do not match the voxels");
    assert!(n[2] <= NW * 64, "{path}: {} slices along z; this prototype takes at most {}", n[2], NW * 64);
    // 3-byte cells: the density and a 14-bit normal code (the central
    // difference gradient's direction, octahedral, 128 × 128)
    let mut vox = vec![0u8; d.len() * 3 + 256];
    let at = |i: usize, j: usize, k: usize| d[i.min(n[0] - 1) + n[0] * (j.min(n[1] - 1) + n[1] * k.min(n[2] - 1))] as f32;
    for k in 0..n[2] {
        for j in 0..n[1] {
            for i in 0..n[0] {
                let b = i + n[0] * (j + n[1] * k);
                let g = [
                    at(i + 1, j, k) - at(i.saturating_sub(1), j, k),
                    at(i, j + 1, k) - at(i, j.saturating_sub(1), k),
                    at(i, j, k + 1) - at(i, j, k.saturating_sub(1)),
                ];
                let l1 = g[0].abs() + g[1].abs() + g[2].abs();
                let code = if l1 == 0.0 {
                    0
                } else {
                    let (mut x, mut y) = (g[0] / l1, g[1] / l1);
                    if g[2] < 0.0 {
                        (x, y) = ((1.0 - y.abs()) * x.signum(), (1.0 - x.abs()) * y.signum());
                    }
                    let q = |t: f32| ((t * 0.5 + 0.5) * 127.0).round() as u16;
                    q(x) + 128 * q(y)
                };
                vox[3 * b] = d[b];
                [vox[3 * b + 1], vox[3 * b + 2]] = code.to_le_bytes();
            }
        }
    }
    let mut cellmax = vec![0u8; d.len()];
    for k in 0..n[2] {
        for j in 0..n[1] - 1 {
            for i in 0..n[0] - 1 {
                let b = i + n[0] * (j + n[1] * k);
                cellmax[b] = d[b].max(d[b + 1]).max(d[b + n[0]]).max(d[b + n[0] + 1]);
            }
        }
    }
    let mut den = d.to_vec();
    den.resize(d.len() + 256, 0);
    let code = (0..den.len()).map(|i| if i < d.len() { u16::from_le_bytes([vox[3 * i + 1], vox[3 * i + 2]]) } else { 0 }).collect();
    Vol { n, vox, cellmax, den, code }
}

fn frame(v: &Vol, deg: f64, iso: u8, pad: i64) -> Frame {
    let s = deg.to_radians().tan();
    let [n0, n1, nk] = v.n;
    let w = n0 + (nk as f64 * s).ceil() as usize + 2 * pad as usize;
    let h = n1 + 2 * pad as usize;
    let mut base = vec![0i64; NW * 64];
    let mut wts = vec![0u64; NW * 64];
    let mut wi = vec![0f32; NW * 64];
    let mut wj = vec![0f32; NW * 64];
    let mut fl = vec![0i64; nk];
    for k in 0..nk {
        let tx = k as f64 * s + 0.37;
        let ty = 0.21f64;
        let f = tx.floor();
        fl[k] = f as i64;
        let di = f as i64 - pad;
        let dj = ty.floor() as i64 - pad;
        base[k] = di + n0 as i64 * dj + (n0 * n1 * k) as i64;
        wi[k] = (tx - f) as f32;
        wj[k] = (ty - ty.floor()) as f32;
        wts[k] = wi[k].to_bits() as u64 | (wj[k].to_bits() as u64) << 32;
    }
    let mut mask = vec![0u64; w * h * NW];
    for q in 0..h {
        for p in 0..w {
            let r = q * w + p;
            for k in 0..nk {
                let ci = p as i64 + fl[k] - pad;
                let cj = q as i64 - pad;
                if ci < 0 || cj < 0 || ci >= n0 as i64 - 1 || cj >= n1 as i64 - 1 {
                    continue;
                }
                if v.cellmax[ci as usize + n0 * (cj as usize + n1 * k)] >= iso {
                    mask[r * NW + k / 64] |= 1u64 << (63 - k % 64);
                }
            }
        }
    }
    Frame { w, h, base, wts, wi, wj, mask }
}

/// The bilinear blend of a cell's corners `[v00, v10, v01, v11]` (every
/// variant's sample and the hit's shade-entry blend: one float order).
#[inline(always)]
fn bilerp([v00, v10, v01, v11]: [f32; 4], wi: f32, wj: f32) -> f32 {
    let t = v00 + wi * (v10 - v00);
    let u = v01 + wi * (v11 - v01);
    t + wj * (u - t)
}

/// The sample of the cell at voxel `b` of the 3-byte cells.
#[inline(always)]
fn sample(vox: &[u8], b: usize, n0: usize, wi: f32, wj: f32) -> f32 {
    let d = |o: usize| unsafe { *vox.get_unchecked(3 * (b + o)) } as f32;
    bilerp([d(0), d(1), d(n0), d(n0 + 1)], wi, wj)
}

impl Vol {
    /// The sample of the cell at voxel `b` in slice entry `k` of `f`
    /// (`PLANE`: from the density plane, else from the 3-byte cells).
    #[inline(always)]
    fn sample<const PLANE: bool>(&self, f: &Frame, b: usize, k: usize) -> f32 {
        if PLANE { sample_plane(&self.den, b, self.n[0], f.wi[k], f.wj[k]) } else { sample(&self.vox, b, self.n[0], f.wi[k], f.wj[k]) }
    }

    /// Prefetches the densities' line that the next row of rays reads where
    /// this one reads the cell at voxel `b`.
    #[inline(always)]
    fn prefetch_next_row<const PLANE: bool>(&self, b: usize) {
        let at = b + 2 * self.n[0];
        let p = if PLANE { self.den.as_ptr().wrapping_add(at) } else { self.vox.as_ptr().wrapping_add(3 * at) };
        unsafe { _mm_prefetch(p as *const i8, _MM_HINT_T0) };
    }
}

/// The first word of a depth row with a candidate, `NW` if none (no branch).
#[inline(always)]
fn first_word(w: &[u64]) -> u32 {
    let nz = (w[0] != 0) as u32 | ((w[1] != 0) as u32) << 1 | ((w[2] != 0) as u32) << 2 | ((w[3] != 0) as u32) << 3;
    (nz | 1 << NW).trailing_zeros()
}

/// The next candidate slice of a ray's depth row (`words`), from word `wi`
/// whose unvisited bits are `cur`, in front-to-back order; `None` past the row.
#[inline(always)]
fn next_candidate(words: &[u64], wi: &mut usize, cur: &mut u64) -> Option<usize> {
    while *cur == 0 {
        *wi += 1;
        if *wi == NW {
            return None;
        }
        *cur = words[*wi];
    }
    let pos = cur.leading_zeros() as usize;
    *cur &= !(1u64 << 63 >> pos);
    Some(*wi * 64 + pos)
}

/// Scalar, per ray (the crate's shape): returns visits.
fn render_scalar(v: &Vol, f: &Frame, iso: f32, prefetch: bool, out_k: &mut [u32], out_d: &mut [f32]) -> usize {
    render_strips::<false>(v, f, iso, prefetch, f.w, out_k, out_d)
}

/// Per ray, the rays in strips of `sw` (the frame's width: row by row);
/// `PLANE`: 8-bit densities in a plane of their own.
fn render_strips<const PLANE: bool>(
    v: &Vol,
    f: &Frame,
    iso: f32,
    prefetch: bool,
    sw: usize,
    out_k: &mut [u32],
    out_d: &mut [f32],
) -> usize {
    let n0 = v.n[0];
    let mut visits = 0;
    for s0 in (0..f.w).step_by(sw) {
        for q in 0..f.h {
            for p in s0..(s0 + sw).min(f.w) {
                let r = q * f.w + p;
                let rb = (p + n0 * q) as i64;
                let words = &f.mask[r * NW..r * NW + NW];
                let mut wi = 0usize;
                let mut cur = words[0];
                out_k[r] = 0;
                while let Some(k) = next_candidate(words, &mut wi, &mut cur) {
                    let b = (rb + f.base[k]) as usize;
                    if prefetch {
                        v.prefetch_next_row::<PLANE>(b);
                    }
                    visits += 1;
                    let d = v.sample::<PLANE>(f, b, k);
                    if d >= iso {
                        out_k[r] = k as u32 + 1;
                        out_d[r] = d;
                        break;
                    }
                }
            }
        }
    }
    visits
}

/// Two passes a row: first candidates and their samples for every ray with no
/// branch on the sample, then the rays whose first sample fell short walk on.
fn render_2pass(v: &Vol, f: &Frame, iso: f32, out_k: &mut [u32], out_d: &mut [f32], st: &mut Vec<(u64, u32, u32, f32)>) -> usize {
    let n0 = v.n[0];
    let mut visits = 0;
    st.resize(f.w, (0, 0, 0, 0.0));
    // a ray without a candidate samples the stack's first cell and is
    // dropped by its sample of -1
    for q in 0..f.h {
        let rb0 = (n0 * q) as i64;
        for p in 0..f.w {
            let r = q * f.w + p;
            let words = &f.mask[r * NW..r * NW + NW];
            let wi = first_word(words) as usize;
            let cur = if wi < NW { words[wi] } else { 1 };
            let pos = cur.leading_zeros() as usize;
            let k = (wi * 64 + pos).min(NW * 64 - 1);
            let b = if wi < NW { (rb0 + p as i64 + f.base[k]) as usize } else { 0 };
            unsafe { _mm_prefetch(v.vox.as_ptr().add(3 * (b + 2 * n0)) as *const i8, _MM_HINT_T0) };
            let d = sample(&v.vox, b, n0, f.wi[k], f.wj[k]);
            let d = if wi < NW { d } else { -1.0 };
            st[p] = (cur & !(1u64 << 63 >> pos), wi as u32, k as u32, d);
        }
        for p in 0..f.w {
            let r = q * f.w + p;
            let (mut cur, wi0, k0, d0) = st[p];
            out_k[r] = 0;
            if wi0 as usize >= NW {
                continue;
            }
            visits += 1;
            if d0 >= iso {
                out_k[r] = k0 + 1;
                out_d[r] = d0;
                continue;
            }
            let rb = rb0 + p as i64;
            let words = &f.mask[r * NW..r * NW + NW];
            let mut wi = wi0 as usize;
            while let Some(k) = next_candidate(words, &mut wi, &mut cur) {
                let b = (rb + f.base[k]) as usize;
                unsafe { _mm_prefetch(v.vox.as_ptr().add(3 * (b + 2 * n0)) as *const i8, _MM_HINT_T0) };
                visits += 1;
                let d = sample(&v.vox, b, n0, f.wi[k], f.wj[k]);
                if d >= iso {
                    out_k[r] = k as u32 + 1;
                    out_d[r] = d;
                    break;
                }
            }
        }
    }
    visits
}

#[inline(always)]
fn codes(vox: &[u8], b: usize, n0: usize) -> [usize; 4] {
    let c = |o: usize| {
        let i = 3 * (b + o) + 1;
        (u16::from_le_bytes(unsafe { [*vox.get_unchecked(i), *vox.get_unchecked(i + 1)] }) & 0x3fff) as usize
    };
    [c(0), c(1), c(n0), c(n0 + 1)]
}

#[inline(always)]
fn shade4(t: &[[f32; 2]], c: [usize; 4], wi: f32, wj: f32) -> [f32; 2] {
    let e = c.map(|c| unsafe { *t.get_unchecked(c) });
    [0, 1].map(|l| bilerp(e.map(|e| e[l]), wi, wj))
}

#[inline(always)]
fn sample_plane(den: &[u8], b: usize, n0: usize, wi: f32, wj: f32) -> f32 {
    let d = |o: usize| unsafe { *den.get_unchecked(b + o) } as f32;
    bilerp([d(0), d(1), d(n0), d(n0 + 1)], wi, wj)
}

#[inline(always)]
fn codes_plane(code: &[u16], b: usize, n0: usize) -> [usize; 4] {
    unsafe {
        let c = |o: usize| (*code.get_unchecked(b + o) & 0x3fff) as usize;
        [c(0), c(1), c(n0), c(n0 + 1)]
    }
}

/// The whole render: search (as render_scalar with prefetch) and the hit:
/// refinement against the slice before, eight codes through a 128 KB shade
/// table, colour and depth stored. `PLANE`: densities and codes in planes
/// of their own (the search reads 8-bit densities, the hit 16-bit codes);
/// `PCODE`: each visit also prefetches the codes' line of the next row.
fn render_full<const PLANE: bool, const PCODE: bool>(
    v: &Vol,
    f: &Frame,
    iso: f32,
    table: &[[f32; 2]],
    img: &mut [[f32; 4]],
    depth: &mut [f32],
) -> usize {
    let n0 = v.n[0];
    let rgb = [0.9f32, 0.8, 0.7];
    let mut hits = 0;
    let cds = |b: usize| if PLANE { codes_plane(&v.code, b, n0) } else { codes(&v.vox, b, n0) };
    for q in 0..f.h {
        for p in 0..f.w {
            let r = q * f.w + p;
            let rb = (p + n0 * q) as i64;
            let words = &f.mask[r * NW..r * NW + NW];
            let mut wi = 0usize;
            let mut cur = words[0];
            let mut below_k = usize::MAX;
            let mut below_d = 0f32;
            img[r] = [0.0; 4];
            while let Some(k) = next_candidate(words, &mut wi, &mut cur) {
                let b = (rb + f.base[k]) as usize;
                v.prefetch_next_row::<PLANE>(b);
                if PCODE {
                    unsafe { _mm_prefetch(v.code.as_ptr().wrapping_add(b + 2 * n0) as *const i8, _MM_HINT_T0) };
                }
                let d = v.sample::<PLANE>(f, b, k);
                if d >= iso {
                    hits += 1;
                    let (dp, bp, kp) = if k == 0 {
                        (0.0, b, 0)
                    } else {
                        let bp = (rb + f.base[k - 1]) as usize;
                        let dp = if below_k == k - 1 { below_d } else { v.sample::<PLANE>(f, bp, k - 1) };
                        (dp, bp, k - 1)
                    };
                    let t = ((iso - dp) / (d - dp)).clamp(0.0, 1.0);
                    let s1 = shade4(table, cds(b), f.wi[k], f.wj[k]);
                    let s0 = shade4(table, cds(bp), f.wi[kp], f.wj[kp]);
                    let df = s0[0] + t * (s1[0] - s0[0]);
                    let sp = s0[1] + t * (s1[1] - s0[1]);
                    img[r] = [rgb[0] * df + sp, rgb[1] * df + sp, rgb[2] * df + sp, 1.0];
                    depth[r] = kp as f32 + t;
                    break;
                }
                below_k = k;
                below_d = d;
            }
        }
    }
    hits
}

/// L rays in flight, branch-free retire and refill (cmov), one visit a lane an
/// iteration; hits recorded and written after the row.
#[inline(never)]
fn render_lanes<const L: usize>(
    v: &Vol,
    f: &Frame,
    iso: f32,
    out_k: &mut [u32],
    out_d: &mut [f32],
    list: &mut Vec<(u32, u32)>,
    hl: &mut Vec<(u32, u32, f32)>,
) -> usize {
    let n0 = v.n[0];
    let mut visits = 0usize;
    list.resize(f.w + L + 1, (0, 0));
    hl.resize(f.w + L + 1, (0, 0, 0.0));
    let vox = v.vox.as_ptr();
    for q in 0..f.h {
        let row = q * f.w;
        out_k[row..row + f.w].iter_mut().for_each(|x| *x = 0);
        // rays with a candidate and their first nonzero word
        let mut m = 0usize;
        for p in 0..f.w {
            let w = &f.mask[(row + p) * NW..(row + p) * NW + NW];
            let fw = first_word(w);
            list[m] = (p as u32, fw);
            m += (fw < NW as u32) as usize;
        }
        // sentinels past the list: dead lanes (ray u32::MAX), never recorded
        for e in &mut list[m..m + L + 1] {
            *e = (u32::MAX, 0);
        }
        let mut next = 0usize;
        let mut nh = 0usize;
        let mut lr = [u32::MAX; L];
        let mut lw = [0usize; L];
        let mut lc = [0u64; L];
        let load = |e: (u32, u32)| -> (u32, usize, u64) {
            if e.0 == u32::MAX { (u32::MAX, 0, 1u64) } else { (e.0, e.1 as usize, f.mask[(row + e.0 as usize) * NW + e.1 as usize]) }
        };
        for l in 0..L {
            let (r, w, c) = load(list[next]);
            next += 1;
            lr[l] = r;
            lw[l] = w;
            lc[l] = c;
        }
        let mut live = L.min(m);
        while live > 0 {
            for l in 0..L {
                let cur = lc[l];
                let pos = cur.leading_zeros() as usize;
                let k = lw[l] * 64 + pos;
                let dead = lr[l] == u32::MAX;
                let p = if dead { 0 } else { lr[l] as usize };
                let rb = (p + n0 * q) as i64;
                let b = if dead { 0 } else { (rb + f.base[k.min(NW * 64 - 1)]) as usize };
                unsafe { _mm_prefetch(vox.add(3 * (b + 2 * n0)) as *const i8, _MM_HINT_T0) };
                let d = sample(&v.vox, b, n0, f.wi[k.min(NW * 64 - 1)], f.wj[k.min(NW * 64 - 1)]);
                let hit = (d >= iso) & !dead;
                visits += !dead as usize;
                hl[nh] = (lr[l], k as u32, d);
                nh += hit as usize;
                let mut c2 = cur & !(1u64 << 63 >> pos);
                let mut w2 = lw[l];
                if c2 == 0 && !hit && !dead {
                    // this word is spent: the next with a candidate
                    loop {
                        w2 += 1;
                        if w2 == NW {
                            break;
                        }
                        c2 = f.mask[(row + p) * NW + w2];
                        if c2 != 0 {
                            break;
                        }
                    }
                }
                let retire = hit | (c2 == 0 && !dead);
                let (nr, nw, nc) = load(list[next]);
                next += retire as usize;
                live -= (retire && nr == u32::MAX) as usize;
                lr[l] = if retire { nr } else { lr[l] };
                lw[l] = if retire { nw } else { w2 };
                lc[l] = if retire { nc } else { c2 };
            }
        }
        for &(r, k, d) in &hl[..nh] {
            out_k[row + r as usize] = k + 1;
            out_d[row + r as usize] = d;
        }
    }
    visits
}

struct Hits {
    lr: Vec<u32>,
    lw: Vec<u32>,
    r: Vec<u32>,
    k: Vec<u32>,
    d: Vec<f32>,
}

#[derive(Clone, Copy)]
struct Packet {
    r: __m512i,
    w: __m512i,
    wend: __m512i,
    kbase: __m512i,
    cur: __m512i,
    rb: __m512i,
    active: u8,
    need: u8,
    next: i64,
    end: i64,
}

struct Ctx {
    n0: i64,
    words: *const i64,
    tbase: *const i64,
    twts: *const i64,
    vox: *const i32,
    invw: f64,
    w: i64,
    iso: f32,
    lr: *const u32,
    lw: *const u32,
}

#[target_feature(enable = "avx512f,avx512cd,avx512vl,avx512dq,avx512bw,bmi2,popcnt")]
#[inline]
unsafe fn step(c: &Ctx, pk: &mut Packet, hits: &mut Hits, nh: &mut usize, visits: &mut usize) -> bool {
    let one = _mm512_set1_epi64(1);
    if pk.need == 0 && pk.active == 0 {
        return false;
    }
    if pk.need != 0 {
        let avail = (pk.need.count_ones() as i64).min(pk.end - pk.next) as u32;
        let fill = _pdep_u32((1u32 << avail) - 1, pk.need as u32) as u8;
        if fill != 0 {
            let lr = _mm256_maskz_expand_epi32(fill, _mm256_loadu_si256(c.lr.add(pk.next as usize) as *const __m256i));
            let lw = _mm256_maskz_expand_epi32(fill, _mm256_loadu_si256(c.lw.add(pk.next as usize) as *const __m256i));
            let newr = _mm512_cvtepi32_epi64(lr);
            let nw = _mm512_cvtepi32_epi64(lw);
            pk.r = _mm512_mask_blend_epi64(fill, pk.r, newr);
            let nws = _mm512_slli_epi64(newr, 2);
            pk.w = _mm512_mask_blend_epi64(fill, pk.w, nw);
            pk.wend = _mm512_mask_blend_epi64(fill, pk.wend, _mm512_add_epi64(nws, _mm512_set1_epi64(NW as i64)));
            pk.kbase = _mm512_mask_blend_epi64(fill, pk.kbase, _mm512_slli_epi64(_mm512_sub_epi64(nw, nws), 6));
            let wf = _mm512_set1_epi64(c.w);
            let qf = _mm512_roundscale_pd(_mm512_mul_pd(_mm512_cvtepi64_pd(newr), _mm512_set1_pd(c.invw)), _MM_FROUND_TO_NEG_INF);
            let mut q = _mm512_cvtpd_epi64(qf);
            let qw = _mm512_mullo_epi64(q, wf);
            q = _mm512_mask_sub_epi64(q, _mm512_cmpgt_epi64_mask(qw, newr), q, one);
            let qw1 = _mm512_add_epi64(_mm512_mullo_epi64(q, wf), wf);
            q = _mm512_mask_add_epi64(q, _mm512_cmple_epi64_mask(qw1, newr), q, one);
            let nrb = _mm512_add_epi64(newr, _mm512_mullo_epi64(q, _mm512_set1_epi64(c.n0 - c.w)));
            pk.rb = _mm512_mask_blend_epi64(fill, pk.rb, nrb);
            pk.cur = _mm512_mask_i64gather_epi64::<8>(pk.cur, fill, nw, c.words);
            pk.next += avail as i64;
        }
        pk.active = (pk.active & !pk.need) | fill;
        pk.need = 0;
        if pk.active == 0 {
            return false;
        }
    }
    let z = _mm512_mask_cmpeq_epi64_mask(pk.active, pk.cur, _mm512_setzero_si512());
    pk.w = _mm512_mask_add_epi64(pk.w, z, pk.w, one);
    pk.kbase = _mm512_mask_add_epi64(pk.kbase, z, pk.kbase, _mm512_set1_epi64(64));
    let exh = _mm512_mask_cmpeq_epi64_mask(z, pk.w, pk.wend);
    pk.cur = _mm512_mask_i64gather_epi64::<8>(pk.cur, z & !exh, pk.w, c.words);
    let vis = pk.active & !z;
    *visits += vis.count_ones() as usize;
    let pos = _mm512_lzcnt_epi64(pk.cur);
    let k = _mm512_add_epi64(pk.kbase, pos);
    pk.cur = _mm512_mask_andnot_epi64(pk.cur, vis, _mm512_srlv_epi64(_mm512_set1_epi64(i64::MIN), pos), pk.cur);
    let base = _mm512_mask_i64gather_epi64::<8>(_mm512_setzero_si512(), vis, k, c.tbase);
    let b = _mm512_add_epi64(pk.rb, base);
    let a = _mm512_add_epi64(b, _mm512_slli_epi64(b, 1));
    {
        let mut pa = [0i64; 8];
        _mm512_storeu_si512(pa.as_mut_ptr() as *mut _, _mm512_add_epi64(a, _mm512_set1_epi64(6 * c.n0)));
        let vb = c.vox as *const i8;
        for x in pa {
            _mm_prefetch(vb.wrapping_offset(x as isize), _MM_HINT_T0);
        }
    }
    let top = _mm512_mask_i64gather_epi32::<1>(_mm256_setzero_si256(), vis, a, c.vox);
    let bot = _mm512_mask_i64gather_epi32::<1>(_mm256_setzero_si256(), vis, _mm512_add_epi64(a, _mm512_set1_epi64(3 * c.n0)), c.vox);
    let wt = _mm512_mask_i64gather_epi64::<8>(_mm512_setzero_si512(), vis, k, c.twts);
    let wi = _mm256_castsi256_ps(_mm512_cvtepi64_epi32(wt));
    let wj = _mm256_castsi256_ps(_mm512_cvtepi64_epi32(_mm512_srli_epi64(wt, 32)));
    let ff = _mm256_set1_epi32(0xff);
    let d00 = _mm256_cvtepi32_ps(_mm256_and_si256(top, ff));
    let d10 = _mm256_cvtepi32_ps(_mm256_srli_epi32(top, 24));
    let d01 = _mm256_cvtepi32_ps(_mm256_and_si256(bot, ff));
    let d11 = _mm256_cvtepi32_ps(_mm256_srli_epi32(bot, 24));
    let t = _mm256_add_ps(d00, _mm256_mul_ps(wi, _mm256_sub_ps(d10, d00)));
    let u = _mm256_add_ps(d01, _mm256_mul_ps(wi, _mm256_sub_ps(d11, d01)));
    let d = _mm256_add_ps(t, _mm256_mul_ps(wj, _mm256_sub_ps(u, t)));
    let hit = _mm256_mask_cmp_ps_mask(vis, d, _mm256_set1_ps(c.iso), _CMP_GE_OQ);
    let n = *nh;
    _mm256_storeu_si256(hits.r.as_mut_ptr().add(n) as *mut __m256i, _mm256_maskz_compress_epi32(hit, _mm512_cvtepi64_epi32(pk.r)));
    _mm256_storeu_si256(hits.k.as_mut_ptr().add(n) as *mut __m256i, _mm256_maskz_compress_epi32(hit, _mm512_cvtepi64_epi32(k)));
    _mm256_storeu_ps(hits.d.as_mut_ptr().add(n), _mm256_maskz_compress_ps(hit, d));
    *nh = n + hit.count_ones() as usize;
    pk.need = hit | exh;
    true
}

#[inline(never)]
#[target_feature(enable = "avx512f,avx512cd,avx512vl,avx512dq,avx512bw,bmi2,popcnt")]
unsafe fn render_simd<const P: usize>(v: &Vol, f: &Frame, iso: f32, hits: &mut Hits, out_k: &mut [u32], out_d: &mut [f32]) -> usize {
    let nr = f.w * f.h;
    hits.lr.resize(nr + 16, 0);
    hits.lw.resize(nr + 16, 0);
    let mut m = 0usize;
    let wp = f.mask.as_ptr();
    let mut r = 0usize;
    while r + 2 <= nr {
        let x = _mm512_loadu_si512(wp.add(r * NW) as *const _);
        let t = _mm512_test_epi64_mask(x, x) as u32;
        let a = t & 15;
        let b = t >> 4;
        *hits.lr.get_unchecked_mut(m) = r as u32;
        *hits.lw.get_unchecked_mut(m) = (r * NW) as u32 + (a | 16).trailing_zeros();
        m += (a != 0) as usize;
        *hits.lr.get_unchecked_mut(m) = r as u32 + 1;
        *hits.lw.get_unchecked_mut(m) = ((r + 1) * NW) as u32 + (b | 16).trailing_zeros();
        m += (b != 0) as usize;
        r += 2;
    }
    while r < nr {
        if let Some(w) = (0..NW).find(|&w| f.mask[r * NW + w] != 0) {
            hits.lr[m] = r as u32;
            hits.lw[m] = (r * NW + w) as u32;
            m += 1;
        }
        r += 1;
    }
    let nrays = m as i64;
    let c = Ctx {
        lr: hits.lr.as_ptr(),
        lw: hits.lw.as_ptr(),
        n0: v.n[0] as i64,
        words: f.mask.as_ptr() as *const i64,
        tbase: f.base.as_ptr(),
        twts: f.wts.as_ptr() as *const i64,
        vox: v.vox.as_ptr() as *const i32,
        invw: 1.0 / f.w as f64,
        w: f.w as i64,
        iso,
    };
    let z = _mm512_setzero_si512();
    let mut pks = [Packet { r: z, w: z, wend: z, kbase: z, cur: z, rb: z, active: 0, need: 0xff, next: 0, end: 0 }; P];
    for (i, pk) in pks.iter_mut().enumerate() {
        pk.next = nrays * i as i64 / P as i64;
        pk.end = nrays * (i as i64 + 1) / P as i64;
    }
    let mut nh = 0usize;
    let mut visits = 0usize;
    hits.r.resize(f.w * f.h + 8, 0);
    hits.k.resize(f.w * f.h + 8, 0);
    hits.d.resize(f.w * f.h + 8, 0.0);
    loop {
        let mut any = false;
        for pk in pks.iter_mut() {
            any |= step(&c, pk, hits, &mut nh, &mut visits);
        }
        if !any {
            break;
        }
    }
    out_k.iter_mut().for_each(|x| *x = 0);
    for i in 0..nh {
        let rr = hits.r[i] as usize;
        out_k[rr] = hits.k[i] + 1;
        out_d[rr] = hits.d[i];
    }
    visits
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).map(|s| s.as_str()).unwrap_or("head256.den");
    let rounds: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(7);
    let iso = 52u8;
    let v = load(path);
    let simd = is_x86_feature_detected!("avx512f")
        && is_x86_feature_detected!("avx512cd")
        && is_x86_feature_detected!("avx512dq")
        && is_x86_feature_detected!("avx512vl")
        && is_x86_feature_detected!("bmi2");
    // the z-axis frames of the rotation: 0..45 degrees about y
    let frames: Vec<Frame> = (0..=45).map(|d| frame(&v, (d as f64).min(44.9), iso, 1)).collect();
    let names = [
        "scalar, no prefetch",
        "scalar, next-row prefetch",
        "scalar, 1-byte density plane",
        "scalar, strips of 64 rays",
        "scalar, two passes a row",
        "scalar, 3 rays in flight (cmov)",
        "AVX-512 packets of 8 rays",
        "AVX-512, 2 packets interleaved",
        "whole render: search + hit (refine, shade, store)",
        "whole render, density and code planes",
        "whole render, density and code planes, codes prefetched too",
    ];
    let nv = names.len();
    let mut times = vec![Vec::new(); nv];
    let mut visits = vec![0usize; nv];
    let mut hits = Hits { lr: vec![], lw: vec![], r: vec![], k: vec![], d: vec![] };
    let mut list = Vec::new();
    let mut hl = Vec::new();
    let mut st: Vec<(u64, u32, u32, f32)> = Vec::new();
    let table: Vec<[f32; 2]> = (0..16384).map(|i| [(i % 97) as f32 / 97.0, (i % 31) as f32 / 60.0]).collect();
    let mut nframes = 0;
    // the reference of every frame: the plain scalar search
    let refs: Vec<(Vec<u32>, Vec<f32>)> = frames
        .iter()
        .map(|f| {
            let (mut k, mut d) = (vec![0u32; f.w * f.h], vec![0f32; f.w * f.h]);
            render_scalar(&v, f, iso as f32, false, &mut k, &mut d);
            (k, d)
        })
        .collect();
    // each round runs every variant over all frames, the variants in a rotated order
    for round in 0..rounds {
        nframes += frames.len();
        for step in 0..nv {
            let var = (step + round) % nv;
            for (fi, f) in frames.iter().enumerate() {
                let n = f.w * f.h;
                let (k0, d0) = (&refs[fi].0, &refs[fi].1);
                if (var == 6 || var == 7) && !simd {
                    continue;
                }
                let (mut k, mut d) = (vec![0u32; n], vec![0f32; n]);
                let mut img = vec![[0f32; 4]; n];
                let mut dep = vec![0f32; n];
                let t = Instant::now();
                visits[var] += match var {
                    0 => render_scalar(&v, f, iso as f32, false, &mut k, &mut d),
                    1 => render_scalar(&v, f, iso as f32, true, &mut k, &mut d),
                    2 => render_strips::<true>(&v, f, iso as f32, true, f.w, &mut k, &mut d),
                    3 => render_strips::<false>(&v, f, iso as f32, true, 64, &mut k, &mut d),
                    4 => render_2pass(&v, f, iso as f32, &mut k, &mut d, &mut st),
                    5 => render_lanes::<3>(&v, f, iso as f32, &mut k, &mut d, &mut list, &mut hl),
                    6 => unsafe { render_simd::<1>(&v, f, iso as f32, &mut hits, &mut k, &mut d) },
                    7 => unsafe { render_simd::<2>(&v, f, iso as f32, &mut hits, &mut k, &mut d) },
                    8 => render_full::<false, false>(&v, f, iso as f32, &table, &mut img, &mut dep),
                    9 => render_full::<true, false>(&v, f, iso as f32, &table, &mut img, &mut dep),
                    _ => render_full::<true, true>(&v, f, iso as f32, &table, &mut img, &mut dep),
                };
                times[var].push(t.elapsed().as_secs_f64() * 1e3);
                if var >= 8 {
                    assert!((0..n).all(|r| (k0[r] != 0) == (img[r][3] != 0.0)), "{}: other hits", names[var]);
                } else {
                    assert_eq!(k0, &k, "{}: other hit slices", names[var]);
                    assert!((0..n).all(|r| k0[r] == 0 || d0[r].to_bits() == d[r].to_bits()), "{}: other samples", names[var]);
                }
            }
        }
    }
    println!("{} frames ({} rounds of {}), median and mean ms a frame, one thread:", nframes, rounds, frames.len());
    for var in 0..nv {
        let mut t = times[var].clone();
        if t.is_empty() {
            println!("| {} | (no AVX-512) |", names[var]);
            continue;
        }
        t.sort_by(|a, b| a.partial_cmp(b).unwrap());
        let mean = t.iter().sum::<f64>() / t.len() as f64;
        println!("| {} | {:.3} | {:.3} | {:.0} |", names[var], t[t.len() / 2], mean, visits[var] as f64 / nframes as f64);
    }
}
