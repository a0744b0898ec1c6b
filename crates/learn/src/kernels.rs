//! How candle's CPU matrix products use the cores.
//!
//! candle hands every matrix product to the `gemm` crate, which splits a product over rayon's
//! threads once it holds more than `48 * 48 * 256` multiply-adds. The learners' products are
//! small (minibatches of 64 to 4,096 rows through 256-wide layers), and on the 2-core machine
//! the split costs about what it gains on a quiet machine and collapses when the cores are
//! busy with anything else (the environments stepping, another job, a build): measured in
//! docs/BENCHMARKS.md, "One thread per matrix product". The `crm` binary therefore runs each
//! product on one thread; the parallelism is across environments, not inside a product.
//! The setting is process-wide (a `gemm` global); a split and an unsplit product give the
//! same bits, as each output element is summed by one thread either way.

/// Runs every matrix product on the calling thread.
pub fn one_thread_per_product() {
    gemm::set_threading_threshold(usize::MAX);
}

/// `gemm`'s default: products above its threshold are split over rayon's threads.
pub fn split_products() {
    gemm::set_threading_threshold(gemm::DEFAULT_THREADING_THRESHOLD);
}

/// Whether products are split over threads now.
pub fn products_split() -> bool {
    gemm::get_threading_threshold() != usize::MAX
}

#[cfg(test)]
mod tests {
    use candle_core::{Device, Tensor};

    use super::*;

    #[test]
    fn a_product_gives_the_same_bits_split_or_not() {
        let values = |n: usize, k: u32| -> Vec<f32> {
            (0..n)
                .map(|i| {
                    ((i as u32).wrapping_mul(2_654_435_761).wrapping_add(k) % 1000) as f32 / 997.0
                        - 0.5
                })
                .collect()
        };
        let a = Tensor::from_vec(values(512 * 256, 1), (512, 256), &Device::Cpu).expect("a");
        let b = Tensor::from_vec(values(256 * 256, 2), (256, 256), &Device::Cpu).expect("b");
        split_products();
        assert!(products_split());
        let split = a.matmul(&b).expect("split").to_vec2::<f32>().expect("read");
        one_thread_per_product();
        assert!(!products_split());
        let single = a
            .matmul(&b)
            .expect("single")
            .to_vec2::<f32>()
            .expect("read");
        split_products();
        assert_eq!(split, single);
    }
}
