use agp_shared_types::{GRID_CELLS, GRID_SIDE};
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatMut, MatRef, Par};

use crate::Grid;
use crate::simd::Simd;

const N: usize = GRID_SIDE;

/// How [`GaussianSmoother`] computes the separable Gaussian filter. All three give the same
/// result up to f32 rounding; cells off the grid count as zero (no reflection).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SmoothingMethod {
    /// Two 1D passes (rows, then columns), each a few `axpy`s over whole rows written for
    /// auto-vectorisation. The fastest; the default.
    #[default]
    Separable,
    /// `K * A * K^T` as two dense faer matrix products, `K` the banded 128 x 128 kernel
    /// matrix built once.
    FaerMatmul,
    /// The naive 2D convolution with the outer-product kernel: the reference, slow.
    Direct2d,
}

/// Gaussian smoothing of a [`Grid`], with every buffer (kernel, kernel matrix, scratch)
/// allocated once at construction: smoothing allocates nothing.
///
/// The kernel is the sampled Gaussian `exp(-d^2 / (2 sigma^2))` for `|d| <= ceil(3 sigma)`
/// cells, normalised to sum 1, so the sum of a grid is preserved away from the borders.
pub struct GaussianSmoother {
    sigma_cells: f64,
    radius: usize,
    method: SmoothingMethod,
    /// `2 * radius + 1` taps, centre at `radius`.
    kernel: Vec<f32>,
    /// One row with `radius` zeros each side.
    padded_row: Vec<f32>,
    /// Result of the first pass, between `radius` rows of zeros above and below (never
    /// written), so the second pass needs no bounds tests.
    scratch: Vec<f32>,
    /// The widest vector build of the separable passes this CPU runs.
    simd: Simd,
    /// Banded kernel matrix `K[r][c] = kernel[c - r + radius]`.
    kernel_matrix: Mat<f32>,
    /// `K * A`.
    product: Mat<f32>,
}

impl GaussianSmoother {
    /// A smoother of standard deviation `sigma_cells` (in cells), using
    /// [`SmoothingMethod::default`].
    ///
    /// Panics if `sigma_cells` is not finite and positive, or so large that the kernel is
    /// wider than the grid.
    #[track_caller]
    pub fn new(sigma_cells: f64) -> Self {
        assert!(
            sigma_cells.is_finite() && sigma_cells > 0.0,
            "sigma must be finite and positive, got {sigma_cells}"
        );
        let radius = (3.0 * sigma_cells).ceil() as usize;
        assert!(
            radius < N,
            "sigma of {sigma_cells} cells is too wide for a {N}-cell grid"
        );
        let taps: Vec<f64> = (0..=2 * radius)
            .map(|t| {
                let d = t as f64 - radius as f64;
                (-d * d / (2.0 * sigma_cells * sigma_cells)).exp()
            })
            .collect();
        let total: f64 = taps.iter().sum();
        let kernel: Vec<f32> = taps.iter().map(|t| (t / total) as f32).collect();
        let kernel_matrix = Mat::from_fn(N, N, |r, c| {
            let d = c as isize - r as isize;
            if d.unsigned_abs() <= radius {
                kernel[(d + radius as isize) as usize]
            } else {
                0.0
            }
        });
        Self {
            sigma_cells,
            radius,
            method: SmoothingMethod::default(),
            kernel,
            padded_row: vec![0.0; N + 2 * radius],
            scratch: vec![0.0; GRID_CELLS + 2 * radius * N],
            simd: Simd::detect(),
            kernel_matrix,
            product: Mat::zeros(N, N),
        }
    }

    /// A smoother of standard deviation `sigma_m` (metres) for grids of `cell_size_m` cells.
    #[track_caller]
    pub fn from_sigma_m(sigma_m: f64, cell_size_m: f64) -> Self {
        Self::new(sigma_m / cell_size_m)
    }

    /// The same smoother using `method` by default.
    pub fn with_method(mut self, method: SmoothingMethod) -> Self {
        self.method = method;
        self
    }

    /// Standard deviation, cells.
    pub fn sigma_cells(&self) -> f64 {
        self.sigma_cells
    }

    /// Half-width of the kernel, cells (`ceil(3 sigma)`).
    pub fn radius(&self) -> usize {
        self.radius
    }

    /// The normalised 1D kernel, `2 * radius + 1` taps, centre at index `radius`.
    pub fn kernel(&self) -> &[f32] {
        &self.kernel
    }

    /// The method [`GaussianSmoother::smooth`] uses.
    pub fn method(&self) -> SmoothingMethod {
        self.method
    }

    /// Smooths `src` into `dst` (which takes `src`'s geometry) with the default method.
    pub fn smooth(&mut self, src: &Grid, dst: &mut Grid) {
        self.smooth_with(self.method, src, dst);
    }

    /// Smooths `grid` in place with the default method.
    pub fn smooth_in_place(&mut self, grid: &mut Grid) {
        match self.method {
            SmoothingMethod::Separable => {
                self.rows_pass(grid.cells());
                self.columns_pass(grid.cells_mut());
            }
            SmoothingMethod::FaerMatmul => {
                self.left_product(grid.cells());
                self.right_product(grid.cells_mut());
            }
            SmoothingMethod::Direct2d => {
                // The middle of `scratch` (its margins stay zero for the separable passes).
                let start = self.radius * N;
                let copy = &mut self.scratch[start..start + GRID_CELLS];
                copy.copy_from_slice(grid.cells());
                Self::direct(&self.kernel, self.radius, copy, grid.cells_mut());
            }
        }
    }

    /// Smooths `src` into `dst` (which takes `src`'s geometry) with `method`.
    pub fn smooth_with(&mut self, method: SmoothingMethod, src: &Grid, dst: &mut Grid) {
        dst.set_geometry_from(src);
        match method {
            SmoothingMethod::Separable => {
                self.rows_pass(src.cells());
                self.columns_pass(dst.cells_mut());
            }
            SmoothingMethod::FaerMatmul => {
                self.left_product(src.cells());
                self.right_product(dst.cells_mut());
            }
            SmoothingMethod::Direct2d => {
                Self::direct(&self.kernel, self.radius, src.cells(), dst.cells_mut());
            }
        }
    }

    /// Horizontal pass: the middle of `scratch` = `src` convolved along x.
    fn rows_pass(&mut self, src: &[f32]) {
        let out = &mut self.scratch[self.radius * N..self.radius * N + GRID_CELLS];
        #[cfg(target_arch = "x86_64")]
        match self.simd {
            Simd::Avx512 => {
                // SAFETY: `simd` is `Avx512` only when this CPU reported AVX-512F and FMA
                // (`Simd::detect`, or `Simd::runnable` in the tests), the features the
                // function is compiled for.
                unsafe { rows_pass_avx512(&self.kernel, &mut self.padded_row, src, out) };
                return;
            }
            Simd::Avx2 => {
                // SAFETY: `simd` is `Avx2` only when this CPU reported FMA and AVX2 or
                // AVX-512F, which includes AVX2 (`Simd::detect`, or `Simd::runnable` in the
                // tests): the features the function is compiled for.
                unsafe { rows_pass_avx2(&self.kernel, &mut self.padded_row, src, out) };
                return;
            }
            Simd::Baseline => {}
        }
        rows_pass_body::<false>(&self.kernel, &mut self.padded_row, src, out);
    }

    /// Vertical pass: `dst` = the first pass's result convolved along y.
    fn columns_pass(&self, dst: &mut [f32]) {
        #[cfg(target_arch = "x86_64")]
        match self.simd {
            Simd::Avx512 => {
                // SAFETY: `simd` is `Avx512` only when this CPU reported AVX-512F and FMA
                // (`Simd::detect`, or `Simd::runnable` in the tests), the features the
                // function is compiled for.
                unsafe { columns_pass_avx512(&self.kernel, &self.scratch, dst) };
                return;
            }
            Simd::Avx2 => {
                // SAFETY: `simd` is `Avx2` only when this CPU reported FMA and AVX2 or
                // AVX-512F, which includes AVX2 (`Simd::detect`, or `Simd::runnable` in the
                // tests): the features the function is compiled for.
                unsafe { columns_pass_avx2(&self.kernel, &self.scratch, dst) };
                return;
            }
            Simd::Baseline => {}
        }
        columns_pass_body::<false>(&self.kernel, &self.scratch, dst);
    }

    /// `product = K * A`, `A` the grid (rows along y).
    fn left_product(&mut self, src: &[f32]) {
        let a = MatRef::from_row_major_slice(src, N, N);
        matmul(
            self.product.as_mut(),
            Accum::Replace,
            self.kernel_matrix.as_ref(),
            a,
            1.0,
            Par::Seq,
        );
    }

    /// `dst = product * K^T`.
    fn right_product(&self, dst: &mut [f32]) {
        let out = MatMut::from_row_major_slice_mut(dst, N, N);
        matmul(
            out,
            Accum::Replace,
            self.product.as_ref(),
            self.kernel_matrix.transpose(),
            1.0,
            Par::Seq,
        );
    }

    /// The naive 2D convolution.
    fn direct(kernel: &[f32], r: usize, src: &[f32], dst: &mut [f32]) {
        let n = N as isize;
        let r = r as isize;
        for j in 0..n {
            for i in 0..n {
                let mut acc = 0.0_f32;
                for dy in -r..=r {
                    let y = j + dy;
                    if !(0..n).contains(&y) {
                        continue;
                    }
                    let ky = kernel[(dy + r) as usize];
                    for dx in -r..=r {
                        let x = i + dx;
                        if (0..n).contains(&x) {
                            acc += ky * kernel[(dx + r) as usize] * src[(y * n + x) as usize];
                        }
                    }
                }
                dst[(j * n + i) as usize] = acc;
            }
        }
    }
}

/// Lanes accumulated together in registers by the separable passes.
const BLOCK: usize = 32;

/// `w * x + a`, fused when the caller is compiled with FMA (unfused `mul_add` would call
/// a slow software routine).
#[inline(always)]
fn madd<const FMA: bool>(w: f32, x: f32, a: f32) -> f32 {
    if FMA { w.mul_add(x, a) } else { a + w * x }
}

/// `out` (N x N) = `src` convolved along x with `kernel` (2r + 1 taps), through `padded`
/// (N + 2r, zero margins).
#[inline(always)]
fn rows_pass_body<const FMA: bool>(
    kernel: &[f32],
    padded: &mut [f32],
    src: &[f32],
    out: &mut [f32],
) {
    let r = kernel.len() / 2;
    for (src_row, out_row) in src.chunks_exact(N).zip(out.chunks_exact_mut(N)) {
        padded[r..r + N].copy_from_slice(src_row);
        for (b, out_block) in out_row.chunks_exact_mut(BLOCK).enumerate() {
            let base = b * BLOCK;
            let mut acc = [0.0_f32; BLOCK];
            let centre = &padded[base + r..base + r + BLOCK];
            for (a, &x) in acc.iter_mut().zip(centre) {
                *a = kernel[r] * x;
            }
            for d in 1..=r {
                let w = kernel[r + d];
                let left = &padded[base + r - d..base + r - d + BLOCK];
                let right = &padded[base + r + d..base + r + d + BLOCK];
                for ((a, &x), &y) in acc.iter_mut().zip(left).zip(right) {
                    *a = madd::<FMA>(w, x + y, *a);
                }
            }
            out_block.copy_from_slice(&acc);
        }
    }
}

/// `dst` (N x N) = the N x N grid between the r zero rows of `src` ((N + 2r) x N)
/// convolved along y with `kernel`.
#[inline(always)]
fn columns_pass_body<const FMA: bool>(kernel: &[f32], src: &[f32], dst: &mut [f32]) {
    let r = kernel.len() / 2;
    for (j, out_row) in dst.chunks_exact_mut(N).enumerate() {
        // Output row j is centred on source row j + r.
        let row = |k: usize, b: usize| &src[k * N + b..k * N + b + BLOCK];
        for (b, out_block) in (0..N).step_by(BLOCK).zip(out_row.chunks_exact_mut(BLOCK)) {
            let mut acc = [0.0_f32; BLOCK];
            for (a, &x) in acc.iter_mut().zip(row(j + r, b)) {
                *a = kernel[r] * x;
            }
            for d in 1..=r {
                let w = kernel[r + d];
                for ((a, &x), &y) in acc.iter_mut().zip(row(j + r - d, b)).zip(row(j + r + d, b)) {
                    *a = madd::<FMA>(w, x + y, *a);
                }
            }
            out_block.copy_from_slice(&acc);
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn rows_pass_avx2(kernel: &[f32], padded: &mut [f32], src: &[f32], out: &mut [f32]) {
    rows_pass_body::<true>(kernel, padded, src, out);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn columns_pass_avx2(kernel: &[f32], src: &[f32], dst: &mut [f32]) {
    columns_pass_body::<true>(kernel, src, dst);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,fma")]
fn rows_pass_avx512(kernel: &[f32], padded: &mut [f32], src: &[f32], out: &mut [f32]) {
    rows_pass_body::<true>(kernel, padded, src, out);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,fma")]
fn columns_pass_avx512(kernel: &[f32], src: &[f32], dst: &mut [f32]) {
    columns_pass_body::<true>(kernel, src, dst);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every vector build this CPU runs gives the baseline build's result (the public tests
    /// see only the widest one).
    #[test]
    fn every_vector_build_smooths_as_the_baseline() {
        let mut smoother = GaussianSmoother::new(2.0);
        let src: Vec<f32> = (0..GRID_CELLS)
            .map(|c| ((c * 7919) % 1009) as f32 / 1009.0)
            .collect();
        let run = |smoother: &mut GaussianSmoother, simd: Simd| {
            smoother.simd = simd;
            let mut dst = vec![0.0_f32; GRID_CELLS];
            smoother.rows_pass(&src);
            smoother.columns_pass(&mut dst);
            dst
        };
        let baseline = run(&mut smoother, Simd::Baseline);
        for &simd in Simd::runnable() {
            let out = run(&mut smoother, simd);
            let worst = out
                .iter()
                .zip(&baseline)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0_f32, f32::max);
            // FMA rounds once where the baseline rounds twice.
            assert!(
                worst < 1e-6,
                "{simd:?} differs from the baseline by {worst}"
            );
        }
    }
}
