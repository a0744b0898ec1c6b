//! How fast candle multiplies the matrices our networks use, on this machine: the ceiling
//! for the learners' updates (docs/BENCHMARKS.md, "How fast can CRM-SAC's update be").
//! `cargo run --release -p crm-learn --example matmul`

use candle_core::{Device, Tensor};

fn main() -> candle_core::Result<()> {
    let device = Device::Cpu;
    // (rows, inner, columns): a 256-row batch through 256x256 and the first layer, a bigger
    // batch, and PPO's 64-row minibatch.
    for (m, k, n) in [
        (256, 256, 256),
        (256, 52, 256),
        (512, 256, 256),
        (64, 256, 256),
    ] {
        let a = Tensor::randn(0f32, 1.0, (m, k), &device)?;
        let b = Tensor::randn(0f32, 1.0, (k, n), &device)?;
        for _ in 0..20 {
            a.matmul(&b)?;
        }
        let reps = 2000;
        let start = std::time::Instant::now();
        for _ in 0..reps {
            a.matmul(&b)?;
        }
        let secs = start.elapsed().as_secs_f64();
        let gflops = 2.0 * (m * k * n) as f64 * f64::from(reps) / secs / 1e9;
        println!(
            "{m}x{k}x{n}: {:.1} us, {gflops:.1} GFLOP/s",
            secs / f64::from(reps) * 1e6
        );
    }
    Ok(())
}
