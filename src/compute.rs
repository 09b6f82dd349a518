//! Where the tensors run: the device (`cpu`, `cuda`, `cuda:N`) and the CPU thread pools.

use anyhow::{bail, Result};
use tch::Device;

/// Parses `cpu`, `cuda` or `cuda:N`; a CUDA device must be usable by this build.
pub fn parse_device(s: &str) -> Result<Device> {
    let device = match s {
        "cpu" => Device::Cpu,
        "cuda" => Device::Cuda(0),
        _ => match s.strip_prefix("cuda:").and_then(|n| n.parse().ok()) {
            Some(n) => Device::Cuda(n),
            None => bail!("--device {s}: expected cpu, cuda or cuda:N"),
        },
    };
    if device != Device::Cpu && !tch::Cuda::is_available() {
        bail!(
            "--device {s}: CUDA is not available to this build (libtorch without CUDA, or no GPU)"
        );
    }
    Ok(device)
}

/// Where a step's tensors run, as given (`--device`, `--threads`): applied when the step starts
/// its tensor work, so that its earlier checks fail first.
#[derive(Clone, Debug)]
pub struct Compute {
    /// `cpu`, `cuda` or `cuda:N`.
    pub device: String,
    /// CPU threads (torch and rayon).
    pub threads: usize,
}

impl Compute {
    pub fn new(device: &str, threads: usize) -> Compute {
        Compute {
            device: device.to_string(),
            threads,
        }
    }

    /// Sets the thread pools, then parses the device.
    pub fn apply(&self) -> Result<Device> {
        set_threads(self.threads, self.threads);
        parse_device(&self.device)
    }
}

/// Thread budget: torch and rayon (nearest-neighbour queries, metrics) pools.
pub fn set_threads(torch: usize, rayon: usize) {
    tch::set_num_threads(torch.max(1) as i32);
    // Fails only if the pool already exists (a second call in tests): keep that one.
    let _ = rayon::ThreadPoolBuilder::new()
        .num_threads(rayon.max(1))
        .build_global();
}

/// Keeps freed memory in the process heap instead of returning it to the kernel. A training step
/// allocates and frees the same few-MB tensors hundreds of times; above glibc's default mmap
/// threshold each one is a fresh mapping whose pages the kernel faults in and zeroes again
/// (`clear_page_erms` was a fifth of the training thread's profile).
pub fn reuse_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only tunes the allocator; called before the training allocations.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20); // glibc's maximum
        libc::mallopt(libc::M_TRIM_THRESHOLD, i32::MAX);
    }
}
