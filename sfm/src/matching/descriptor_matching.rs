//! Descriptor matching (paper 003, section 3: matching features between images):
//! [`match_descriptors`] finds brute-force nearest and second-nearest neighbours in L2 between
//! two sets of u8 SIFT descriptors, with Lowe's ratio test (Lowe 2004, section 7.1: the nearest
//! distance below `ratio` times the second; 0.8 as in the paper and COLMAP) and the mutual
//! check (the nearest neighbour of the match, searched the other way, is the query). The
//! squared distances `|a|² + |b|² - 2 a·b` are exact integers: the dot products run on
//! the u8 descriptors in i32 (AVX-512 VNNI or AVX2, chosen at run time, see
//! [`DistanceKernel`]; faer's f32 GEMM, exact below 2²⁴, where neither exists), in register
//! tiles of 4 queries x 32-64 candidates over cache-sized candidate chunks, with query
//! blocks on rayon. The same pass keeps each query's two nearest candidates and each
//! candidate's nearest query, so it gives the ratio test and the mutual check at once, and
//! every kernel gives the brute-force result bit for bit (ties to the lower index).

use fresco_core::config::{ConfigError, require};
use rayon::prelude::*;
use serde::Serialize;

use crate::features::feature_file::{DESCRIPTOR_LEN, Descriptor};

/// Descriptor matching settings.
#[derive(Clone, Debug, Serialize)]
pub struct MatchingConfig {
    /// Lowe's ratio: nearest distance < `ratio` x second-nearest distance. Default: `0.8`.
    pub ratio: f32,
    /// Keep a match only if it is also the nearest neighbour in the other direction. Default: `true`.
    pub mutual: bool,
    /// After a pair is verified with an epipolar geometry (calibrated or uncalibrated), match
    /// it again restricted to that geometry ([`crate::matching::guided_matching`]) and verify the
    /// guided matches. Default: `false` (COLMAP's default too): on templeSparseRing with its
    /// calibration it adds 30-50% true matches per pair and halves the median camera centre
    /// error (0.119% -> 0.074% of the scene), but on sceaux_castle's repeated facade it adds
    /// matches that are wrong along the epipolar lines (mean reprojection 0.32 -> 0.41 px,
    /// centres 0.028% -> 0.057% from COLMAP's); see bench/RESULTS.md.
    pub guided: bool,
}

impl Default for MatchingConfig {
    fn default() -> Self {
        MatchingConfig {
            ratio: 0.8,
            mutual: true,
            guided: false,
        }
    }
}

impl MatchingConfig {
    /// Each field within its meaningful range, else the [`ConfigError`] naming it.
    pub fn check(&self) -> Result<(), ConfigError> {
        require(
            self.ratio > 0.0 && self.ratio <= 1.0,
            "ratio",
            self.ratio,
            "in (0, 1]",
        )
    }
}

/// How the descriptor dot products are computed. Every kernel gives the exact integer
/// distances, so all give identical matches; [`DistanceKernel::best`] picks the fastest this
/// CPU runs (detected at run time).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DistanceKernel {
    /// AVX-512 VNNI `vpdpbusd`: u8 candidate bytes times i8 query bytes, 64 products per
    /// instruction; query bytes >= 128 are split off (`q = lo + 128 hi`) so the sum stays exact.
    Avx512Vnni,
    /// AVX2 `vpmaddwd` on u8 widened to i16 (16 products per instruction, exact in i32).
    Avx2,
    /// faer's f32 matrix products (exact: u8 products summed over 128 entries stay below 2²⁴).
    Portable,
}

impl DistanceKernel {
    /// The kernels this CPU can run, fastest first (the portable one is always last).
    pub fn available() -> Vec<DistanceKernel> {
        let mut k = Vec::new();
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx512f")
                && std::arch::is_x86_feature_detected!("avx512vnni")
            {
                k.push(DistanceKernel::Avx512Vnni);
            }
            if std::arch::is_x86_feature_detected!("avx2") {
                k.push(DistanceKernel::Avx2);
            }
        }
        k.push(DistanceKernel::Portable);
        k
    }

    /// The fastest available kernel.
    pub fn best() -> DistanceKernel {
        static BEST: std::sync::OnceLock<DistanceKernel> = std::sync::OnceLock::new();
        *BEST.get_or_init(|| DistanceKernel::available()[0])
    }
}

/// Best and second-best squared distance of one query and the best candidate's index
/// (`u32::MAX` if none). Distances are exact integers.
#[derive(Clone, Copy, Debug)]
struct Nearest2 {
    d1: i32,
    i1: u32,
    d2: i32,
}

/// Nearest query of each candidate: (squared distance, query index).
type ColumnBest = (i32, u32);

/// Lexicographic (distance, index) minimum: ties go to the lower query index, so the result
/// does not depend on how the queries were split between threads.
fn merge_columns(a: &mut [ColumnBest], b: &[ColumnBest]) {
    for (x, y) in a.iter_mut().zip(b) {
        if *y < *x {
            *x = *y;
        }
    }
}

/// Matches descriptors `d1` (queries) against `d2`: `[index in d1, index in d2]` pairs that pass
/// the ratio test and, if enabled, the mutual check; ascending in the first index. Uses
/// [`DistanceKernel::best`].
///
/// One pass over all query-candidate pairs keeps, for each query, its two nearest candidates
/// (the ratio test) and, for each candidate, its nearest query (the mutual check), from the
/// exact integer squared distances `|a|² + |b|² - 2 a·b`; ties go to the lower index, as a
/// stable brute-force sort would give.
pub fn match_descriptors(
    d1: &[Descriptor],
    d2: &[Descriptor],
    config: &MatchingConfig,
) -> Vec<[u32; 2]> {
    match_descriptors_with(DistanceKernel::best(), d1, d2, config)
}

/// [`match_descriptors`] with a chosen kernel (falls back to the portable one if the CPU lacks
/// the requested instructions). For tests and benchmarks: all kernels give the same matches.
pub fn match_descriptors_with(
    kernel: DistanceKernel,
    d1: &[Descriptor],
    d2: &[Descriptor],
    config: &MatchingConfig,
) -> Vec<[u32; 2]> {
    if d1.is_empty() || d2.len() < 2 {
        return Vec::new();
    }
    let kernel = if DistanceKernel::available().contains(&kernel) {
        kernel
    } else {
        DistanceKernel::Portable
    };
    let (rows, cols) = match kernel {
        #[cfg(target_arch = "x86_64")]
        DistanceKernel::Avx512Vnni => simd::nearest::<simd::Vnni>(d1, d2),
        #[cfg(target_arch = "x86_64")]
        DistanceKernel::Avx2 => simd::nearest::<simd::Avx2>(d1, d2),
        _ => nearest_portable(d1, d2),
    };
    // The ratio test as the brute-force reference states it, in f64 on exact integers.
    let ratio2 = (config.ratio as f64).powi(2);
    let mut out = Vec::new();
    for (i, b2) in rows.iter().enumerate() {
        if b2.i1 == u32::MAX || (b2.d1 as f64) >= ratio2 * b2.d2 as f64 {
            continue;
        }
        if config.mutual && cols[b2.i1 as usize].1 != i as u32 {
            continue;
        }
        out.push([i as u32, b2.i1]);
    }
    out
}

/// Query rows per rayon task (and per matrix product) of the portable kernel.
const BLOCK_ROWS: usize = 256;
/// Candidates per matrix product: a 256 x 1024 f32 block of dot products is 1 MiB, the
/// candidates' f32 descriptors 512 KiB, so one product and its scan stay in L2.
const BLOCK_COLS: usize = 1024;

/// Descriptors as one row-major f32 array (`n x 128`) and their squared norms.
fn to_f32(d: &[Descriptor]) -> (Vec<f32>, Vec<f32>) {
    let v: Vec<f32> = d.iter().flat_map(|x| x.map(f32::from)).collect();
    let n = d
        .iter()
        .map(|x| x.iter().map(|&a| f32::from(a) * f32::from(a)).sum())
        .collect();
    (v, n)
}

impl Nearest2 {
    const EMPTY: Nearest2 = Nearest2 {
        d1: i32::MAX,
        i1: u32::MAX,
        d2: i32::MAX,
    };
    #[inline(always)]
    fn push(&mut self, d: i32, i: u32) {
        if d < self.d1 {
            self.d2 = self.d1;
            self.d1 = d;
            self.i1 = i;
        } else if d < self.d2 {
            self.d2 = d;
        }
    }
}

/// The portable kernel: the dot products of a block of queries with a block of candidates
/// are one matrix product (faer's GEMM, exact in f32, so the result does not depend on the
/// block sizes or the summation order), scanned row by row and column by column.
fn nearest_portable(d1: &[Descriptor], d2: &[Descriptor]) -> (Vec<Nearest2>, Vec<ColumnBest>) {
    let (a, na) = to_f32(d1);
    let (b, nb) = to_f32(d2);
    let n2 = d2.len();
    // All candidates as the 128 x n2 right-hand side (column j = descriptor j).
    let rhs = faer::MatRef::from_column_major_slice(&b, DESCRIPTOR_LEN, n2);
    type State = (Vec<(usize, Vec<Nearest2>)>, Vec<ColumnBest>);
    let init = || -> State { (Vec::new(), vec![(i32::MAX, u32::MAX); n2]) };
    let (mut rows, cols) = a
        .par_chunks(BLOCK_ROWS * DESCRIPTOR_LEN)
        .enumerate()
        .fold(init, |(mut rows, mut cols), (block, queries)| {
            let first = block * BLOCK_ROWS;
            let m = queries.len() / DESCRIPTOR_LEN;
            let lhs = faer::MatRef::from_row_major_slice(queries, m, DESCRIPTOR_LEN);
            let mut best = vec![Nearest2::EMPTY; m];
            let mut dots = vec![0f32; m * BLOCK_COLS.min(n2)];
            for c0 in (0..n2).step_by(BLOCK_COLS) {
                let c1 = (c0 + BLOCK_COLS).min(n2);
                let nc = c1 - c0;
                let block_dots = &mut dots[..m * nc];
                faer::linalg::matmul::matmul(
                    faer::MatMut::from_row_major_slice_mut(block_dots, m, nc),
                    faer::Accum::Replace,
                    lhs,
                    rhs.subcols(c0, nc),
                    1.0f32,
                    faer::Par::Seq,
                );
                for (i, (row, b2)) in block_dots.chunks_exact(nc).zip(&mut best).enumerate() {
                    let q = first + i;
                    let nq = na[q];
                    for ((&dot, &nc2), (j, col)) in row
                        .iter()
                        .zip(&nb[c0..c1])
                        .zip(cols[c0..c1].iter_mut().enumerate())
                    {
                        // Exact integers below 2²⁴ in f32.
                        let d = (nq + nc2 - 2.0 * dot).max(0.0) as i32;
                        b2.push(d, (c0 + j) as u32);
                        if d < col.0 {
                            *col = (d, q as u32);
                        }
                    }
                }
            }
            rows.push((block, best));
            (rows, cols)
        })
        .reduce(init, |(mut ra, mut ca), (rb, cb)| {
            ra.extend(rb);
            merge_columns(&mut ca, &cb);
            (ra, ca)
        });
    rows.sort_by_key(|r| r.0);
    (rows.into_iter().flat_map(|r| r.1).collect(), cols)
}

/// The integer SIMD kernels (x86-64, chosen at run time).
///
/// Layout: candidates are packed in groups of `LANES` (one vector register of i32 lanes, one
/// candidate per lane): for each step of `STEP` descriptor entries, the lanes' entries side by
/// side, so one load gives `LANES` candidates' next entries and the query's entries are one
/// broadcast 32-bit word. A tile of 4 queries x `TILE_GROUPS` groups accumulates its dot
/// products in registers over the 128 entries, then turns them into distances and updates,
/// per lane, each query's best and second-best (distance, candidate) and, per candidate, its
/// best (distance, query). Queries run on rayon in blocks of `TASK_ROWS`; candidates are
/// visited in chunks of `CHUNK` so a chunk's packed data stays in L2 while the block's tiles
/// pass over it. At the end each query's per-lane bests are reduced to its two nearest.
///
/// Padding: the candidate count is rounded up to whole tiles with zero descriptors whose norm
/// is `PAD_NORM` (farther than any real distance, below 2⁸·128·255² ≈ 8.3e6 by far), and the
/// queries to whole tiles with the same, so padding never wins a row or a column.
#[cfg(target_arch = "x86_64")]
// Register tiles are indexed by (row, group): index loops read best.
#[allow(clippy::needless_range_loop)]
mod simd {
    use super::{ColumnBest, Nearest2, merge_columns};
    use crate::features::feature_file::Descriptor;
    use rayon::prelude::*;
    use std::arch::x86_64::*;

    /// `[e(0), e(1), e(2), e(3)]` written out: closures (`std::array::from_fn`) would not
    /// inherit the kernels' target features, and their intrinsics would not inline.
    macro_rules! arr4 {
        (|$i:ident| $e:expr) => {
            [
                {
                    let $i = 0usize;
                    $e
                },
                {
                    let $i = 1usize;
                    $e
                },
                {
                    let $i = 2usize;
                    $e
                },
                {
                    let $i = 3usize;
                    $e
                },
            ]
        };
    }
    macro_rules! arr2 {
        (|$i:ident| $e:expr) => {
            [
                {
                    let $i = 0usize;
                    $e
                },
                {
                    let $i = 1usize;
                    $e
                },
            ]
        };
    }

    /// Norm of padding descriptors: larger than any real squared distance (at most
    /// 128 x 255² < 2²³), small enough that two of them added stay below 2³¹.
    const PAD_NORM: i32 = 1 << 28;
    /// Queries per register tile.
    const TILE_ROWS: usize = 4;
    /// Queries per rayon task.
    const TASK_ROWS: usize = 64;

    /// One SIMD kernel: how candidates and queries are packed, and the tile.
    pub(super) trait Kernel {
        /// Candidates per vector register.
        const LANES: usize;
        /// Vector groups per tile.
        const TILE_GROUPS: usize;
        /// Candidates per cache chunk (a multiple of `LANES * TILE_GROUPS`).
        const CHUNK: usize;
        /// Bytes of one packed group.
        const GROUP_BYTES: usize;
        /// 32-bit words of one packed query.
        const QUERY_WORDS: usize;
        /// Packs candidate `c`'s descriptor into lane `lane` of a group's bytes.
        fn pack_candidate(d: &Descriptor, lane: usize, group: &mut [u8]);
        /// Packs a query into `out` (`QUERY_WORDS` words); true if the high part is needed.
        fn pack_query(d: &Descriptor, out: &mut [i32]) -> bool;
        /// One tile over groups `g0..g1` (a multiple of `TILE_GROUPS` apart).
        ///
        /// # Safety
        /// The CPU supports the kernel's instructions; `state` holds 4 rows x `LANES` lanes;
        /// the slices cover `g1` groups.
        unsafe fn tile(
            args: &TileArgs,
            g0: usize,
            g1: usize,
            state: &mut RowState,
            cols: &mut Cols,
        );
    }

    /// The inputs of one tile.
    pub(super) struct TileArgs<'a> {
        /// Packed candidates (all groups).
        pub packed: &'a [u8],
        /// Squared norms of the (padded) candidates.
        pub cand_norm: &'a [i32],
        /// The tile's 4 packed queries, `QUERY_WORDS` words each.
        pub queries: &'a [i32],
        /// Whether any of the 4 queries needs the high part.
        pub high: bool,
        /// The 4 queries' squared norms.
        pub norms: [i32; TILE_ROWS],
        /// The 4 queries' indices.
        pub index: [u32; TILE_ROWS],
    }

    /// Per-lane best, best index, second best of 4 rows (`4 * LANES` each).
    pub(super) struct RowState<'a> {
        pub b1: &'a mut [i32],
        pub i1: &'a mut [u32],
        pub b2: &'a mut [i32],
    }

    /// Per-candidate best distance and query.
    pub(super) struct Cols<'a> {
        pub d: &'a mut [i32],
        pub q: &'a mut [u32],
    }

    pub(super) struct Vnni;
    pub(super) struct Avx2;

    impl Kernel for Vnni {
        const LANES: usize = 16;
        const TILE_GROUPS: usize = 4;
        const CHUNK: usize = 1024;
        // 32 steps of 4 entries x 16 lanes.
        const GROUP_BYTES: usize = 2048;
        // 32 words of the low 7 bits, 32 of the high bit.
        const QUERY_WORDS: usize = 64;
        fn pack_candidate(d: &Descriptor, lane: usize, group: &mut [u8]) {
            for s in 0..32 {
                group[s * 64 + lane * 4..s * 64 + lane * 4 + 4]
                    .copy_from_slice(&d[4 * s..4 * s + 4]);
            }
        }
        fn pack_query(d: &Descriptor, out: &mut [i32]) -> bool {
            let mut high = false;
            for s in 0..32 {
                let q = &d[4 * s..4 * s + 4];
                out[s] = i32::from_le_bytes(std::array::from_fn(|k| q[k] & 0x7f));
                out[32 + s] = i32::from_le_bytes(std::array::from_fn(|k| q[k] >> 7));
                high |= out[32 + s] != 0;
            }
            high
        }
        unsafe fn tile(
            args: &TileArgs,
            g0: usize,
            g1: usize,
            state: &mut RowState,
            cols: &mut Cols,
        ) {
            // SAFETY: the caller guarantees AVX-512F + VNNI and the slice extents.
            unsafe { vnni_tile(args, g0, g1, state, cols) }
        }
    }

    #[target_feature(enable = "avx512f,avx512vnni")]
    unsafe fn vnni_tile(
        args: &TileArgs,
        g0: usize,
        g1: usize,
        state: &mut RowState,
        cols: &mut Cols,
    ) {
        unsafe {
            let q = args.queries.as_ptr();
            let mut b1: [__m512i; 4] =
                arr4!(|r| _mm512_loadu_si512(state.b1.as_ptr().add(16 * r).cast()));
            let mut i1: [__m512i; 4] =
                arr4!(|r| _mm512_loadu_si512(state.i1.as_ptr().add(16 * r).cast()));
            let mut b2: [__m512i; 4] =
                arr4!(|r| _mm512_loadu_si512(state.b2.as_ptr().add(16 * r).cast()));
            let iota = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
            let nq: [__m512i; 4] = arr4!(|r| _mm512_set1_epi32(args.norms[r]));
            let qi: [__m512i; 4] = arr4!(|r| _mm512_set1_epi32(args.index[r] as i32));
            let mut g = g0;
            while g < g1 {
                let base = args.packed.as_ptr().add(g * 2048);
                let mut acc = [[_mm512_setzero_si512(); 4]; 4];
                if args.high {
                    // a·q = a·lo + 128 a·hi: the high bits first, scaled, then the low bits.
                    for s in 0..32 {
                        let t: [__m512i; 4] =
                            arr4!(|j| _mm512_loadu_si512(base.add(j * 2048 + s * 64).cast()));
                        for r in 0..4 {
                            let qb = _mm512_set1_epi32(*q.add(r * 64 + 32 + s));
                            for j in 0..4 {
                                acc[r][j] = _mm512_dpbusd_epi32(acc[r][j], t[j], qb);
                            }
                        }
                    }
                    for row in acc.iter_mut() {
                        for a in row.iter_mut() {
                            *a = _mm512_slli_epi32::<7>(*a);
                        }
                    }
                }
                for s in 0..32 {
                    let t: [__m512i; 4] =
                        arr4!(|j| _mm512_loadu_si512(base.add(j * 2048 + s * 64).cast()));
                    for r in 0..4 {
                        let qb = _mm512_set1_epi32(*q.add(r * 64 + s));
                        for j in 0..4 {
                            acc[r][j] = _mm512_dpbusd_epi32(acc[r][j], t[j], qb);
                        }
                    }
                }
                for j in 0..4 {
                    let c = (g + j) * 16;
                    let nt = _mm512_loadu_si512(args.cand_norm.as_ptr().add(c).cast());
                    let idx = _mm512_add_epi32(iota, _mm512_set1_epi32(c as i32));
                    let mut cd = _mm512_setzero_si512();
                    let mut cq = _mm512_setzero_si512();
                    for r in 0..4 {
                        // |q|² + |t|² - 2 q·t
                        let d = _mm512_sub_epi32(
                            _mm512_add_epi32(nt, nq[r]),
                            _mm512_slli_epi32::<1>(acc[r][j]),
                        );
                        let m = _mm512_cmplt_epi32_mask(d, b1[r]);
                        b2[r] = _mm512_mask_blend_epi32(m, _mm512_min_epi32(b2[r], d), b1[r]);
                        b1[r] = _mm512_min_epi32(b1[r], d);
                        i1[r] = _mm512_mask_blend_epi32(m, i1[r], idx);
                        if r == 0 {
                            cd = d;
                            cq = qi[0];
                        } else {
                            let mc = _mm512_cmplt_epi32_mask(d, cd);
                            cd = _mm512_min_epi32(cd, d);
                            cq = _mm512_mask_blend_epi32(mc, cq, qi[r]);
                        }
                    }
                    let pd = cols.d.as_mut_ptr().add(c);
                    let pq = cols.q.as_mut_ptr().add(c);
                    let old_d = _mm512_loadu_si512(pd.cast());
                    let old_q = _mm512_loadu_si512(pq.cast());
                    let mc = _mm512_cmplt_epi32_mask(cd, old_d);
                    _mm512_storeu_si512(pd.cast(), _mm512_min_epi32(old_d, cd));
                    _mm512_storeu_si512(pq.cast(), _mm512_mask_blend_epi32(mc, old_q, cq));
                }
                g += 4;
            }
            for r in 0..4 {
                _mm512_storeu_si512(state.b1.as_mut_ptr().add(16 * r).cast(), b1[r]);
                _mm512_storeu_si512(state.i1.as_mut_ptr().add(16 * r).cast(), i1[r]);
                _mm512_storeu_si512(state.b2.as_mut_ptr().add(16 * r).cast(), b2[r]);
            }
        }
    }

    impl Kernel for Avx2 {
        const LANES: usize = 8;
        const TILE_GROUPS: usize = 2;
        const CHUNK: usize = 512;
        // 64 steps of 2 i16 entries x 8 lanes.
        const GROUP_BYTES: usize = 2048;
        const QUERY_WORDS: usize = 64;
        fn pack_candidate(d: &Descriptor, lane: usize, group: &mut [u8]) {
            for s in 0..64 {
                let o = s * 32 + lane * 4;
                group[o..o + 2].copy_from_slice(&i16::from(d[2 * s]).to_le_bytes());
                group[o + 2..o + 4].copy_from_slice(&i16::from(d[2 * s + 1]).to_le_bytes());
            }
        }
        fn pack_query(d: &Descriptor, out: &mut [i32]) -> bool {
            for s in 0..64 {
                out[s] = i32::from(d[2 * s]) | (i32::from(d[2 * s + 1]) << 16);
            }
            false
        }
        unsafe fn tile(
            args: &TileArgs,
            g0: usize,
            g1: usize,
            state: &mut RowState,
            cols: &mut Cols,
        ) {
            // SAFETY: the caller guarantees AVX2 and the slice extents.
            unsafe { avx2_tile(args, g0, g1, state, cols) }
        }
    }

    #[target_feature(enable = "avx2")]
    unsafe fn avx2_tile(
        args: &TileArgs,
        g0: usize,
        g1: usize,
        state: &mut RowState,
        cols: &mut Cols,
    ) {
        unsafe {
            let q = args.queries.as_ptr();
            macro_rules! ld {
                ($p:expr) => {
                    _mm256_loadu_si256($p.cast())
                };
            }
            let iota = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
            let mut g = g0;
            while g < g1 {
                let base = args.packed.as_ptr().add(g * 2048);
                let mut acc = [[_mm256_setzero_si256(); 2]; 4];
                for s in 0..64 {
                    let t: [__m256i; 2] =
                        arr2!(|j| _mm256_loadu_si256(base.add(j * 2048 + s * 32).cast()));
                    for r in 0..4 {
                        let qb = _mm256_set1_epi32(*q.add(r * 64 + s));
                        for j in 0..2 {
                            acc[r][j] = _mm256_add_epi32(acc[r][j], _mm256_madd_epi16(t[j], qb));
                        }
                    }
                }
                for j in 0..2 {
                    let c = (g + j) * 8;
                    let nt = ld!(args.cand_norm.as_ptr().add(c));
                    let idx = _mm256_add_epi32(iota, _mm256_set1_epi32(c as i32));
                    let mut cd = _mm256_setzero_si256();
                    let mut cq = _mm256_setzero_si256();
                    for r in 0..4 {
                        let d = _mm256_sub_epi32(
                            _mm256_add_epi32(nt, _mm256_set1_epi32(args.norms[r])),
                            _mm256_slli_epi32::<1>(acc[r][j]),
                        );
                        let pb1 = state.b1.as_mut_ptr().add(8 * r);
                        let pi1 = state.i1.as_mut_ptr().add(8 * r);
                        let pb2 = state.b2.as_mut_ptr().add(8 * r);
                        let (b1, i1, b2) = (ld!(pb1), ld!(pi1), ld!(pb2));
                        let m = _mm256_cmpgt_epi32(b1, d); // d < b1
                        _mm256_storeu_si256(
                            pb2.cast(),
                            _mm256_blendv_epi8(_mm256_min_epi32(b2, d), b1, m),
                        );
                        _mm256_storeu_si256(pb1.cast(), _mm256_min_epi32(b1, d));
                        _mm256_storeu_si256(pi1.cast(), _mm256_blendv_epi8(i1, idx, m));
                        let qr = _mm256_set1_epi32(args.index[r] as i32);
                        if r == 0 {
                            cd = d;
                            cq = qr;
                        } else {
                            let mc = _mm256_cmpgt_epi32(cd, d);
                            cd = _mm256_min_epi32(cd, d);
                            cq = _mm256_blendv_epi8(cq, qr, mc);
                        }
                    }
                    let pd = cols.d.as_mut_ptr().add(c);
                    let pq = cols.q.as_mut_ptr().add(c);
                    let (old_d, old_q) = (ld!(pd), ld!(pq));
                    let mc = _mm256_cmpgt_epi32(old_d, cd);
                    _mm256_storeu_si256(pd.cast(), _mm256_min_epi32(old_d, cd));
                    _mm256_storeu_si256(pq.cast(), _mm256_blendv_epi8(old_q, cq, mc));
                }
                g += 2;
            }
        }
    }

    fn norm(d: &Descriptor) -> i32 {
        d.iter().map(|&v| i32::from(v) * i32::from(v)).sum()
    }

    /// Nearest two candidates of every query and nearest query of every candidate.
    pub(super) fn nearest<K: Kernel>(
        d1: &[Descriptor],
        d2: &[Descriptor],
    ) -> (Vec<Nearest2>, Vec<ColumnBest>) {
        let tile_cols = K::LANES * K::TILE_GROUPS;
        let n2 = d2.len();
        let padded = n2.div_ceil(tile_cols) * tile_cols;
        let groups = padded / K::LANES;
        let mut packed = vec![0u8; groups * K::GROUP_BYTES];
        packed
            .par_chunks_mut(K::GROUP_BYTES)
            .enumerate()
            .for_each(|(g, group)| {
                for lane in 0..K::LANES {
                    if let Some(d) = d2.get(g * K::LANES + lane) {
                        K::pack_candidate(d, lane, group);
                    }
                }
            });
        let mut cand_norm: Vec<i32> = d2.iter().map(norm).collect();
        cand_norm.resize(padded, PAD_NORM);
        let chunk_groups = K::CHUNK / K::LANES;

        type State = (Vec<(usize, Vec<Nearest2>)>, Vec<i32>, Vec<u32>);
        let init = || -> State { (Vec::new(), vec![i32::MAX; padded], vec![u32::MAX; padded]) };
        let (mut rows, mut cols) = d1
            .par_chunks(TASK_ROWS)
            .enumerate()
            .fold(
                init,
                |(mut rows, mut col_d, mut col_q), (block, queries)| {
                    let first = block * TASK_ROWS;
                    let m = queries.len();
                    let tiles = m.div_ceil(TILE_ROWS);
                    let mut qwords = vec![0i32; tiles * TILE_ROWS * K::QUERY_WORDS];
                    let mut high = vec![false; tiles];
                    let mut norms = vec![PAD_NORM; tiles * TILE_ROWS];
                    for (r, q) in queries.iter().enumerate() {
                        high[r / TILE_ROWS] |=
                            K::pack_query(q, &mut qwords[r * K::QUERY_WORDS..][..K::QUERY_WORDS]);
                        norms[r] = norm(q);
                    }
                    let lanes = tiles * TILE_ROWS * K::LANES;
                    let mut b1 = vec![i32::MAX; lanes];
                    let mut i1 = vec![u32::MAX; lanes];
                    let mut b2 = vec![i32::MAX; lanes];
                    let mut cols = Cols {
                        d: &mut col_d,
                        q: &mut col_q,
                    };
                    for g0 in (0..groups).step_by(chunk_groups) {
                        let g1 = (g0 + chunk_groups).min(groups);
                        for t in 0..tiles {
                            let args = TileArgs {
                                packed: &packed,
                                cand_norm: &cand_norm,
                                queries: &qwords[t * TILE_ROWS * K::QUERY_WORDS..]
                                    [..TILE_ROWS * K::QUERY_WORDS],
                                high: high[t],
                                norms: std::array::from_fn(|r| norms[t * TILE_ROWS + r]),
                                index: std::array::from_fn(|r| (first + t * TILE_ROWS + r) as u32),
                            };
                            let s = t * TILE_ROWS * K::LANES..(t + 1) * TILE_ROWS * K::LANES;
                            let mut state = RowState {
                                b1: &mut b1[s.clone()],
                                i1: &mut i1[s.clone()],
                                b2: &mut b2[s],
                            };
                            // SAFETY: `nearest::<K>` is only called when the CPU has K's
                            // instructions; groups g0..g1 are whole tiles within `packed`,
                            // `cand_norm` and `cols` (all `padded` long).
                            unsafe { K::tile(&args, g0, g1, &mut state, &mut cols) };
                        }
                    }
                    // Each query's two nearest over its lanes (ties: the lower candidate index).
                    let best: Vec<Nearest2> = (0..m)
                        .map(|r| {
                            let lane = |k: usize| r * K::LANES + k;
                            let mut k1 = 0;
                            for k in 1..K::LANES {
                                if (b1[lane(k)], i1[lane(k)]) < (b1[lane(k1)], i1[lane(k1)]) {
                                    k1 = k;
                                }
                            }
                            let mut d2 = b2[lane(k1)];
                            for k in (0..K::LANES).filter(|&k| k != k1) {
                                d2 = d2.min(b1[lane(k)]);
                            }
                            Nearest2 {
                                d1: b1[lane(k1)],
                                i1: i1[lane(k1)],
                                d2,
                            }
                        })
                        .collect();
                    rows.push((block, best));
                    (rows, col_d, col_q)
                },
            )
            .map(|(rows, d, q)| (rows, d.into_iter().zip(q).collect::<Vec<ColumnBest>>()))
            .reduce(
                || (Vec::new(), vec![(i32::MAX, u32::MAX); padded]),
                |(mut ra, mut ca), (rb, cb)| {
                    ra.extend(rb);
                    merge_columns(&mut ca, &cb);
                    (ra, ca)
                },
            );
        rows.sort_by_key(|r| r.0);
        cols.truncate(n2);
        (rows.into_iter().flat_map(|r| r.1).collect(), cols)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use fresco_core::Rng;

    pub(crate) fn random_descriptors(n: usize, seed: u64) -> Vec<Descriptor> {
        let mut rng = Rng::new(seed);
        (0..n)
            .map(|_| std::array::from_fn(|_| (rng.uniform() * 120.0) as u8))
            .collect()
    }

    /// The slow obvious implementation: exact integer distances.
    fn brute_force(
        d1: &[Descriptor],
        d2: &[Descriptor],
        ratio: f32,
        mutual: bool,
    ) -> Vec<[u32; 2]> {
        let dist = |a: &Descriptor, b: &Descriptor| -> i64 {
            a.iter()
                .zip(b)
                .map(|(&x, &y)| (x as i64 - y as i64).pow(2))
                .sum()
        };
        let nearest = |q: &Descriptor, set: &[Descriptor]| -> (usize, i64, i64) {
            let mut all: Vec<(i64, usize)> = set
                .iter()
                .enumerate()
                .map(|(j, d)| (dist(q, d), j))
                .collect();
            all.sort();
            (all[0].1, all[0].0, all.get(1).map_or(i64::MAX, |x| x.0))
        };
        let mut out = Vec::new();
        for (i, q) in d1.iter().enumerate() {
            let (j, a, b) = nearest(q, d2);
            if (a as f64) >= (ratio as f64).powi(2) * b as f64 {
                continue;
            }
            if mutual && nearest(&d2[j], d1).0 != i {
                continue;
            }
            out.push([i as u32, j as u32]);
        }
        out
    }

    #[test]
    fn matches_agree_with_brute_force() {
        // Image 2 holds noisy copies of 450 of image 1's 603 descriptors (shuffled) and 1100
        // unrelated ones: three query blocks and two candidate blocks, neither a multiple of
        // the block sizes, so every tail path runs.
        let d1 = random_descriptors(603, 1);
        let mut rng = Rng::new(2);
        let mut d2 = random_descriptors(1100, 3);
        for d in d1.iter().take(450) {
            d2.push(d.map(|v| (v as f64 + rng.range(-6.0, 6.0)).clamp(0.0, 255.0) as u8));
        }
        let mut order: Vec<usize> = (0..d2.len()).collect();
        for i in (1..order.len()).rev() {
            order.swap(i, (rng.uniform() * (i + 1) as f64) as usize);
        }
        let d2: Vec<Descriptor> = order.iter().map(|&i| d2[i]).collect();
        for (ratio, mutual) in [(0.8, true), (0.8, false), (0.95, true), (0.6, false)] {
            let config = MatchingConfig {
                ratio,
                mutual,
                guided: false,
            };
            let reference = brute_force(&d1, &d2, ratio, mutual);
            for kernel in DistanceKernel::available() {
                let fast = match_descriptors_with(kernel, &d1, &d2, &config);
                assert_eq!(fast, reference, "{kernel:?} {config:?}");
            }
        }
        // The copies are found: all 450 survive ratio 0.8 with the mutual check.
        let m = match_descriptors(&d1, &d2, &MatchingConfig::default());
        let correct = m
            .iter()
            .filter(|[i, j]| order[*j as usize] >= 1100 && order[*j as usize] - 1100 == *i as usize)
            .count();
        assert_eq!(correct, 450);
        assert_eq!(m.len(), 450);
    }

    #[test]
    fn every_kernel_is_exact_on_ties_high_bytes_and_odd_sizes() {
        // Entries over the whole u8 range (the VNNI kernel splits bytes >= 128 off), sizes
        // around the tile, lane and task widths, and exact ties: duplicated candidates (equal
        // best and second best: rejected by the ratio test) and duplicated queries (equal
        // column distances: the lower query wins the mutual check).
        let mut rng = Rng::new(11);
        let mut wide = |n: usize| -> Vec<Descriptor> {
            (0..n)
                .map(|_| std::array::from_fn(|_| (rng.uniform() * 256.0).min(255.0) as u8))
                .collect()
        };
        let kernels = DistanceKernel::available();
        for (n1, n2) in [(1, 2), (3, 17), (5, 63), (65, 65), (130, 200), (67, 1029)] {
            let mut d1 = wide(n1);
            let mut d2 = wide(n2);
            // Near copies of some queries among the candidates, so matches exist.
            for k in 0..n1.min(n2) / 2 {
                d2[(7 * k) % n2] = d1[k].map(|v| v.saturating_add((k % 3) as u8));
            }
            if n2 > 4 {
                d2[n2 - 1] = d2[0]; // a tied candidate pair
            }
            if n1 > 3 {
                d1[n1 - 1] = d1[1]; // a tied query pair
            }
            for (ratio, mutual) in [(0.8, true), (0.8, false), (1.0, false)] {
                let reference = brute_force(&d1, &d2, ratio, mutual);
                let config = MatchingConfig {
                    ratio,
                    mutual,
                    guided: false,
                };
                for &kernel in &kernels {
                    let got = match_descriptors_with(kernel, &d1, &d2, &config);
                    assert_eq!(got, reference, "{kernel:?} {n1}x{n2} {config:?}");
                }
            }
        }
        // All-equal candidates: every distance ties, so nothing passes the ratio test.
        let d1 = wide(9);
        let d2 = vec![d1[0]; 40];
        for &kernel in &kernels {
            let m = match_descriptors_with(kernel, &d1, &d2, &MatchingConfig::default());
            assert!(m.is_empty(), "{kernel:?}");
        }
    }

    #[test]
    fn empty_and_tiny_sets() {
        let d = random_descriptors(5, 1);
        let c = MatchingConfig::default();
        assert!(match_descriptors(&[], &d, &c).is_empty());
        assert!(match_descriptors(&d, &[], &c).is_empty());
        assert!(match_descriptors(&d, &d[..1], &c).is_empty());
    }
}
