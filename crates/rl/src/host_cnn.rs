//! The NatureCNN encoder ([`crate::cnn`]) on the host, forward and backward for `n` images:
//! im2col gathers and products through the `gemm` crate (the kernels Burn's flex backend
//! multiplies with, picked for the CPU at run time: AVX2, AVX-512 or NEON).
//!
//! Through the tensor backend a batch-1 encoder pass spent most of its time outside the
//! multiply-adds (a direct conv loop, dispatch and buffer churn). Here each conv layer is one
//! product: activations stay position-major (`[n, h, w, c]`), a layer's patches are an
//! `[n * oh * ow, c * k * k]` matrix gathered in the weights' `(c, ky, kx)` order, so the
//! product with the `[out_c, c * k * k]` weight as stored gives the next layer's input as is.
//! The flatten before the linear layer takes the tensor path's `[c, h, w]` order, so the weights
//! and policy files are the same; `ppo::update`'s tests check both passes against Burn's
//! autodiff.

// Inference builds (`default-features = false`, what agvrl-drive links) run the forward pass only.
#![cfg_attr(not(feature = "train"), allow(dead_code))]

use crate::cnn::{CONV_LAYERS, ImageSpec};
use crate::error::{Result, RlError};
use crate::nets::HostParams;

/// A matrix view: element `(r, c)` at `data[r * rs + c * cs]`.
#[derive(Clone, Copy)]
struct Mat<'a> {
    data: &'a [f32],
    rs: usize,
    cs: usize,
}

impl<'a> Mat<'a> {
    /// A row-major `rows x cols` matrix.
    fn rows(data: &'a [f32], cols: usize) -> Self {
        Self { data, rs: cols, cs: 1 }
    }

    /// The transpose of a row-major matrix with `cols` columns.
    fn t(data: &'a [f32], cols: usize) -> Self {
        Self { data, rs: 1, cs: cols }
    }

    /// Whether the view's last element `(rows - 1, cols - 1)` lies in `data`.
    fn fits(&self, rows: usize, cols: usize) -> bool {
        rows == 0 || cols == 0 || (rows - 1) * self.rs + (cols - 1) * self.cs < self.data.len()
    }
}

/// `dst [m x n] row-major = (dst if accumulate, else 0) + a [m x k] b [k x n]`.
fn matmul(dst: &mut [f32], a: Mat<'_>, b: Mat<'_>, (m, n, k): (usize, usize, usize), accumulate: bool) {
    assert!(
        dst.len() >= m * n && a.fits(m, k) && b.fits(k, n),
        "matmul operands too short"
    );
    if m == 0 || n == 0 {
        return;
    }
    if k == 0 {
        if !accumulate {
            dst[..m * n].fill(0.0);
        }
        return;
    }
    // SAFETY: the assert above keeps every element the strides reach inside its slice; `dst`
    // is borrowed mutably, so it aliases neither operand.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            1,
            n as isize,
            accumulate,
            a.data.as_ptr(),
            a.cs as isize,
            a.rs as isize,
            b.data.as_ptr(),
            b.cs as isize,
            b.rs as isize,
            1.0,
            1.0,
            false,
            false,
            false,
            gemm::Parallelism::None,
        );
    }
}

/// Where a layer reads its input and in which order it gathers a patch: image `i`'s patch at
/// output position `(oy, ox)` is the runs `src[base + r .. base + r + run]` for `r` in `runs`,
/// `base = offset + i * image + oy * step_y + ox * step_x`.
struct Source {
    offset: usize,
    image: usize,
    step_y: usize,
    step_x: usize,
    runs: Vec<usize>,
    run: usize,
}

/// A conv layer's geometry: input channels, output grid, the patch width.
#[derive(Clone, Copy)]
struct Conv {
    in_c: usize,
    k: usize,
    oh: usize,
    ow: usize,
}

impl Conv {
    fn ckk(&self) -> usize {
        self.in_c * self.k * self.k
    }
}

/// The patches of `n` images, `[n * oh * ow, c * k * k]`, into `out`.
fn im2col(src: &[f32], at: &Source, g: Conv, n: usize, out: &mut Vec<f32>) {
    out.clear();
    out.reserve(n * g.oh * g.ow * g.ckk());
    for i in 0..n {
        for oy in 0..g.oh {
            for ox in 0..g.ow {
                let base = at.offset + i * at.image + oy * at.step_y + ox * at.step_x;
                for r in &at.runs {
                    out.extend_from_slice(&src[base + r..base + r + at.run]);
                }
            }
        }
    }
}

/// The adjoint of [`im2col`]: patch gradients `dp` added into `dx` (laid out as `at`).
fn col2im(dp: &[f32], at: &Source, g: Conv, n: usize, dx: &mut [f32]) {
    let mut rows = dp.chunks_exact(at.run);
    for i in 0..n {
        for oy in 0..g.oh {
            for ox in 0..g.ow {
                let base = at.offset + i * at.image + oy * at.step_y + ox * at.step_x;
                for r in &at.runs {
                    let d = rows.next().expect("one run of dp per patch run");
                    dx[base + r..base + r + at.run]
                        .iter_mut()
                        .zip(d)
                        .for_each(|(x, d)| *x += d);
                }
            }
        }
    }
}

/// Rows of `bias`, `rows` times.
fn bias_rows(bias: &[f32], rows: usize, out: &mut Vec<f32>) {
    out.clear();
    out.reserve(rows * bias.len());
    for _ in 0..rows {
        out.extend_from_slice(bias);
    }
}

fn relu(v: &mut [f32]) {
    v.iter_mut().for_each(|x| *x = x.max(0.0));
}

/// `d *= (y > 0)`, a select so the loop vectorises.
fn relu_grad(d: &mut [f32], y: &[f32]) {
    d.iter_mut()
        .zip(y)
        .for_each(|(d, y)| *d = if *y > 0.0 { *d } else { 0.0 });
}

/// `sum over rows` of `m [rows x cols]` added to `out [cols]`.
fn add_col_sums(m: &[f32], cols: usize, out: &mut [f32]) {
    for row in m.chunks_exact(cols) {
        out.iter_mut().zip(row).for_each(|(o, v)| *o += v);
    }
}

/// `[rows x cols]` row-major to `[cols x rows]` row-major.
fn transpose(m: &[f32], rows: usize, cols: usize) -> Vec<f32> {
    let mut t = vec![0.0; m.len()];
    transpose_blocks(m, rows, cols, &mut t);
    t
}

/// Each `[rows x cols]` block of `m` transposed into the same block of `out`.
fn transpose_blocks(m: &[f32], rows: usize, cols: usize, out: &mut [f32]) {
    for (block, t) in m.chunks_exact(rows * cols).zip(out.chunks_exact_mut(rows * cols)) {
        for (r, row) in block.chunks_exact(cols).enumerate() {
            for (c, v) in row.iter().enumerate() {
                t[c * rows + r] = *v;
            }
        }
    }
}

/// The encoder's weights laid out for its products, made once per set of weights (a policy
/// load, a rollout, a minibatch). The first layer gathers its patches from the `[c, h, w]`
/// image in the stored `(c, ky, kx)` order; the others from position-major activations in
/// `(ky, kx, c)` order, where a patch row is `k` runs of `k * c` adjacent values; their
/// weights are permuted to match.
pub(crate) struct HostEncoder {
    spec: ImageSpec,
    convs: [Conv; 3],
    /// Per conv layer, the weight in patch order, `[out_c, ckk]` and transposed `[ckk, out_c]`
    /// (products with a row-major right-hand side ran up to 2x faster at batch 1).
    w: [Vec<f32>; 3],
    wt: [Vec<f32>; 3],
    /// The conv biases, then the linear layer's weight `[n_flatten, features_dim]` and bias.
    b: [Vec<f32>; 3],
    lin_w: Vec<f32>,
    lin_b: Vec<f32>,
}

/// One forward pass of `n` images, kept for the backward pass.
pub(crate) struct EncoderPass {
    n: usize,
    obs_dim: usize,
    /// Per conv layer: its patches and its ReLU output `[n * oh * ow, out_c]`.
    patches: [Vec<f32>; 3],
    outs: [Vec<f32>; 3],
    /// The last conv output flattened in `[c, h, w]` order, `[n, n_flatten]`.
    flat: Vec<f32>,
    /// The encoder's output after ReLU, `[n, features_dim]`.
    pub(crate) features: Vec<f32>,
}

impl HostEncoder {
    /// The encoder of `spec` (already validated) with its 8 tensors `params` (see
    /// [`ImageSpec::param_shapes`]).
    pub(crate) fn new(spec: &ImageSpec, params: &[Vec<f32>]) -> Self {
        let shapes = spec.conv_shapes().expect("a validated image spec");
        let mut in_c = spec.channels;
        let convs: [Conv; 3] = std::array::from_fn(|l| {
            let (c, oh, ow) = shapes[l];
            let g = Conv {
                in_c,
                k: CONV_LAYERS[l].1,
                oh,
                ow,
            };
            in_c = c;
            g
        });
        let w: [Vec<f32>; 3] = std::array::from_fn(|l| {
            let (g, stored) = (convs[l], &params[2 * l]);
            if l == 0 {
                return stored.clone();
            }
            let (kk, ckk) = (g.k * g.k, g.ckk());
            let mut w = vec![0.0; stored.len()];
            for (o, row) in stored.chunks_exact(ckk).enumerate() {
                for c in 0..g.in_c {
                    for q in 0..kk {
                        w[o * ckk + q * g.in_c + c] = row[c * kk + q];
                    }
                }
            }
            w
        });
        let wt = std::array::from_fn(|l| transpose(&w[l], CONV_LAYERS[l].0, convs[l].ckk()));
        Self {
            spec: *spec,
            convs,
            w,
            wt,
            b: std::array::from_fn(|l| params[2 * l + 1].clone()),
            lin_w: params[6].clone(),
            lin_b: params[7].clone(),
        }
    }

    /// Width of the encoder's output.
    pub(crate) fn features_dim(&self) -> usize {
        self.spec.features_dim
    }

    /// Where layer `l` reads: the observation rows (`[c, h, w]` after the vector values) for
    /// the first, the previous layer's position-major output for the others.
    fn source(&self, l: usize, obs_dim: usize) -> Source {
        let (g, s) = (self.convs[l], CONV_LAYERS[l].2);
        if l == 0 {
            let (h, w) = (self.spec.height, self.spec.width);
            Source {
                offset: obs_dim - self.spec.len(),
                image: obs_dim,
                step_y: s * w,
                step_x: s,
                runs: (0..g.in_c)
                    .flat_map(|c| (0..g.k).map(move |ky| c * h * w + ky * w))
                    .collect(),
                run: g.k,
            }
        } else {
            let (c, w) = (g.in_c, self.convs[l - 1].ow);
            Source {
                offset: 0,
                image: self.convs[l - 1].oh * w * c,
                step_y: s * w * c,
                step_x: s * c,
                runs: (0..g.k).map(|ky| ky * w * c).collect(),
                run: g.k * c,
            }
        }
    }

    /// The encoder on `n` observation rows of `obs_dim` values each, the image last in a row.
    pub(crate) fn forward(&self, obs: &[f32], obs_dim: usize, n: usize) -> EncoderPass {
        assert!(
            obs.len() >= n * obs_dim && obs_dim >= self.spec.len(),
            "observation rows too short"
        );
        let mut pass = EncoderPass {
            n,
            obs_dim,
            patches: Default::default(),
            outs: Default::default(),
            flat: Vec::new(),
            features: Vec::new(),
        };
        for (l, (g, (out_c, _, _))) in self.convs.into_iter().zip(CONV_LAYERS).enumerate() {
            let (rows, ckk) = (n * g.oh * g.ow, g.ckk());
            let src: &[f32] = if l == 0 { obs } else { &pass.outs[l - 1] };
            let mut patches = Vec::new();
            im2col(src, &self.source(l, obs_dim), g, n, &mut patches);
            let mut out = Vec::new();
            bias_rows(&self.b[l], rows, &mut out);
            matmul(
                &mut out,
                Mat::rows(&patches, ckk),
                Mat::rows(&self.wt[l], out_c),
                (rows, out_c, ckk),
                true,
            );
            relu(&mut out);
            pass.patches[l] = patches;
            pass.outs[l] = out;
        }
        let (c, hw) = (CONV_LAYERS[2].0, self.convs[2].oh * self.convs[2].ow);
        let nf = c * hw;
        pass.flat = vec![0.0; n * nf];
        // Each image's `[hw, c]` to `[c, hw]`.
        transpose_blocks(&pass.outs[2], hw, c, &mut pass.flat);
        let fd = self.spec.features_dim;
        bias_rows(&self.lin_b, n, &mut pass.features);
        matmul(
            &mut pass.features,
            Mat::rows(&pass.flat, nf),
            Mat::rows(&self.lin_w, fd),
            (n, fd, nf),
            true,
        );
        relu(&mut pass.features);
        pass
    }

    /// `n` observation rows with the image replaced by the encoder's features:
    /// `[vector | features]`, `obs_dim - C*H*W + features_dim` values a row.
    pub(crate) fn encode_rows(&self, obs: &[f32], obs_dim: usize, n: usize) -> (EncoderPass, Vec<f32>) {
        let pass = self.forward(obs, obs_dim, n);
        let v = obs_dim - self.spec.len();
        let fd = self.spec.features_dim;
        let mut x = Vec::with_capacity(n * (v + fd));
        for i in 0..n {
            x.extend_from_slice(&obs[i * obs_dim..i * obs_dim + v]);
            x.extend_from_slice(&pass.features[i * fd..(i + 1) * fd]);
        }
        (pass, x)
    }

    /// Gradients of `sum(features * d_features)` with respect to the encoder's 8 tensors,
    /// added into `grads` (in [`ImageSpec::param_shapes`] order, the stored layout).
    pub(crate) fn backward(&self, pass: &EncoderPass, d_features: &[f32], grads: &mut [Vec<f32>]) {
        let (n, fd) = (pass.n, self.spec.features_dim);
        let (c3, hw) = (CONV_LAYERS[2].0, self.convs[2].oh * self.convs[2].ow);
        let nf = c3 * hw;
        let mut dz = d_features[..n * fd].to_vec();
        relu_grad(&mut dz, &pass.features);
        add_col_sums(&dz, fd, &mut grads[7]);
        matmul(
            &mut grads[6],
            Mat::t(&pass.flat, nf),
            Mat::rows(&dz, fd),
            (nf, fd, n),
            true,
        );
        let mut d_flat = vec![0.0; n * nf];
        matmul(
            &mut d_flat,
            Mat::rows(&dz, fd),
            Mat::t(&self.lin_w, fd),
            (n, nf, fd),
            false,
        );
        // Back to position-major, through conv 3's ReLU.
        let mut dz = vec![0.0; n * nf];
        transpose_blocks(&d_flat, c3, hw, &mut dz);
        relu_grad(&mut dz, &pass.outs[2]);
        let mut dp = Vec::new();
        for l in (0..3).rev() {
            let g = self.convs[l];
            let (rows, out_c, ckk) = (n * g.oh * g.ow, CONV_LAYERS[l].0, g.ckk());
            add_col_sums(&dz, out_c, &mut grads[2 * l + 1]);
            if l == 0 {
                matmul(
                    &mut grads[0],
                    Mat::t(&dz, out_c),
                    Mat::rows(&pass.patches[0], ckk),
                    (out_c, ckk, rows),
                    true,
                );
                break;
            }
            // In patch order, then back to the stored `(c, ky, kx)` order.
            let mut dw = vec![0.0; out_c * ckk];
            matmul(
                &mut dw,
                Mat::t(&dz, out_c),
                Mat::rows(&pass.patches[l], ckk),
                (out_c, ckk, rows),
                false,
            );
            let kk = g.k * g.k;
            for (o, row) in dw.chunks_exact(ckk).enumerate() {
                let stored = &mut grads[2 * l][o * ckk..(o + 1) * ckk];
                for q in 0..kk {
                    for c in 0..g.in_c {
                        stored[c * kk + q] += row[q * g.in_c + c];
                    }
                }
            }
            // The image itself needs no gradient; the layers below do.
            dp.resize(rows * ckk, 0.0);
            matmul(
                &mut dp,
                Mat::rows(&dz, out_c),
                Mat::rows(&self.w[l], ckk),
                (rows, ckk, out_c),
                false,
            );
            let mut dx = vec![0.0; pass.outs[l - 1].len()];
            col2im(&dp, &self.source(l, pass.obs_dim), g, n, &mut dx);
            relu_grad(&mut dx, &pass.outs[l - 1]);
            dz = dx;
        }
    }
}

/// The NatureCNN with its weights on the host, for shape checks, inference
/// and timing.
pub struct Encoder {
    spec: ImageSpec,
    host: HostEncoder,
}

impl Encoder {
    /// An encoder with weights `params`.
    pub fn new(spec: ImageSpec, params: &HostParams) -> Result<Self> {
        if params.shapes != spec.param_shapes()? {
            return Err(RlError::Config("encoder weights do not match the image spec".into()));
        }
        Ok(Self {
            spec,
            host: HostEncoder::new(&spec, &params.data),
        })
    }

    /// `n` rows of `obs_dim` values each -> `n` rows of `obs_dim - C*H*W + features_dim`.
    pub fn forward(&self, obs: &[f32], obs_dim: usize) -> Result<Vec<f32>> {
        self.spec.vector_dim(obs_dim)?;
        if obs_dim == 0 || obs.is_empty() || !obs.len().is_multiple_of(obs_dim) {
            return Err(RlError::Shape {
                what: "observation",
                got: obs.len(),
                dim: obs_dim,
            });
        }
        let n = obs.len() / obs_dim;
        Ok(self.host.encode_rows(obs, obs_dim, n).1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The host encoder (inference, the learners' host path) against the tensor formulation.
    #[test]
    fn host_encoder_matches_the_tensor_encoder() {
        use crate::cnn::encode;
        use crate::nets::Init;
        use crate::rng::Rng;
        use burn::tensor::Tensor;
        let spec = ImageSpec {
            features_dim: 48,
            ..ImageSpec::new(3, 40, 52)
        };
        let params = spec.init(Init::Orthogonal(2f64.sqrt()), &mut Rng::new(4)).unwrap();
        let (n, o) = (3, 4 + spec.len());
        let mut rng = Rng::new(5);
        let obs: Vec<f32> = (0..n * o).map(|_| rng.uniform() as f32).collect();
        let host = Encoder::new(spec, &params).unwrap().forward(&obs, o).unwrap();
        let dev = crate::device::default_device();
        let x = Tensor::<3>::from_data(burn::tensor::TensorData::new(obs, [1, n, o]), &dev);
        let tensor = crate::nets::to_vec(encode(&params.to_device(&dev), &spec, x)).unwrap();
        assert_eq!(host.len(), tensor.len());
        assert!(host.iter().any(|v| *v > 0.0));
        for (k, (h, t)) in host.iter().zip(&tensor).enumerate() {
            assert!((h - t).abs() < 1e-5 + 1e-4 * t.abs(), "[{k}] {h} vs {t}");
        }
    }

    /// The product against a triple loop, for every stride combination the encoder uses.
    #[test]
    fn matmul_of_transposed_views_matches_a_triple_loop() {
        let (m, n, k) = (5, 7, 3);
        let a: Vec<f32> = (0..m * k).map(|v| (v as f32 * 0.37).sin()).collect();
        let b: Vec<f32> = (0..k * n).map(|v| (v as f32 * 0.91).cos()).collect();
        let at: Vec<f32> = (0..k * m).map(|q| a[(q % m) * k + q / m]).collect();
        let bt: Vec<f32> = (0..n * k).map(|q| b[(q % k) * n + q / k]).collect();
        let mut want = vec![1.0f32; m * n];
        for r in 0..m {
            for c in 0..n {
                want[r * n + c] += (0..k).map(|j| a[r * k + j] * b[j * n + c]).sum::<f32>();
            }
        }
        for (av, bv) in [(Mat::rows(&a, k), Mat::rows(&b, n)), (Mat::t(&at, m), Mat::t(&bt, k))] {
            let mut got = vec![1.0f32; m * n];
            matmul(&mut got, av, bv, (m, n, k), true);
            assert!(got.iter().zip(&want).all(|(g, w)| (g - w).abs() < 1e-5), "{got:?}");
        }
    }

    /// `<im2col(x), p> == <x, col2im(p)>` for random x and p, for both gather orders: col2im
    /// is im2col's adjoint.
    #[test]
    fn col2im_is_the_adjoint_of_im2col() {
        let spec = ImageSpec {
            features_dim: 4,
            ..ImageSpec::new(2, 40, 46)
        };
        let params = spec
            .init(crate::nets::Init::TorchDefault, &mut crate::rng::Rng::new(1))
            .unwrap();
        let enc = HostEncoder::new(&spec, &params.data);
        let n = 2;
        for l in 0..3 {
            let g = enc.convs[l];
            let (at, len) = match l {
                0 => (enc.source(0, 3 + spec.len()), n * (3 + spec.len())),
                _ => (enc.source(l, 0), n * enc.convs[l - 1].oh * enc.convs[l - 1].ow * g.in_c),
            };
            let x: Vec<f32> = (0..len).map(|v| (v as f32 * 0.13).sin()).collect();
            let mut cols = Vec::new();
            im2col(&x, &at, g, n, &mut cols);
            assert_eq!(cols.len(), n * g.oh * g.ow * g.ckk());
            let p: Vec<f32> = (0..cols.len()).map(|v| (v as f32 * 0.29).cos()).collect();
            let mut back = vec![0.0; x.len()];
            col2im(&p, &at, g, n, &mut back);
            let lhs: f64 = cols.iter().zip(&p).map(|(a, b)| (*a as f64) * (*b as f64)).sum();
            let rhs: f64 = x.iter().zip(&back).map(|(a, b)| (*a as f64) * (*b as f64)).sum();
            assert!((lhs - rhs).abs() < 1e-3 * (1.0 + lhs.abs()), "layer {l}: {lhs} {rhs}");
        }
    }
}
