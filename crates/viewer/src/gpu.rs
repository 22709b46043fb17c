//! Adapter and device setup, headless or for a window surface.
//!
//! A machine without a GPU still has Mesa's llvmpipe (Vulkan through lavapipe, or GL through EGL);
//! `WGPU_BACKEND=vulkan|gl` picks one. Tests and benchmarks that need an adapter follow one rule:
//! with `WALKTHROUGH_REQUIRE_GPU` set, a missing adapter is a failure; without it, they say so and
//! step aside ([`headless_or_skip`]).

use anyhow::{Context, anyhow};

/// Set in CI (or by hand) to make a missing adapter an error instead of a skipped check.
pub use conventions::require_gpu::VAR as REQUIRE_GPU_VAR;
/// Whether a missing adapter is a failure here.
pub use conventions::require_gpu::required as gpu_required;

pub struct Gpu {
    pub instance: wgpu::Instance,
    pub adapter: wgpu::Adapter,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
}

impl Gpu {
    /// A device for offscreen drawing.
    pub fn headless() -> anyhow::Result<Gpu> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle().with_env());
        pollster::block_on(Self::open(instance, None))
    }

    /// A device able to present to `surface`, which `instance` created.
    pub async fn open(
        instance: wgpu::Instance,
        surface: Option<&wgpu::Surface<'_>>,
    ) -> anyhow::Result<Gpu> {
        let adapter = instance
            .request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                compatible_surface: surface,
                ..Default::default()
            })
            .await
            .map_err(|e| anyhow!("no graphics adapter (not even Mesa's llvmpipe): {e}"))?;
        // The adapter's own limits: a million triangles need a 72 MB vertex buffer, and the table
        // doubles its capacity, so the defaults (256 MiB) would cap it needlessly on a real GPU.
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("viewer"),
                required_limits: adapter.limits(),
                ..Default::default()
            })
            .await
            .context("opening the graphics device")?;
        Ok(Gpu {
            instance,
            adapter,
            device,
            queue,
        })
    }

    /// "Vulkan, llvmpipe (LLVM 15.0.6, 256 bits)" and the like, for logs and BENCHMARKS.md.
    pub fn describe(&self) -> String {
        let info = self.adapter.get_info();
        format!("{:?}, {} ({:?})", info.backend, info.name, info.device_type)
    }

    /// Blocks until the queue has finished everything submitted so far.
    pub fn wait_idle(&self) -> anyhow::Result<()> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| anyhow!("waiting for the GPU: {e}"))
    }
}

/// A headless device, or `Ok(None)` after a clear message when there is none and none is required.
pub fn headless_or_skip(what: &str) -> anyhow::Result<Option<Gpu>> {
    match Gpu::headless() {
        Ok(gpu) => Ok(Some(gpu)),
        Err(e) if gpu_required() => Err(e.context(format!("{what}: {REQUIRE_GPU_VAR} is set"))),
        Err(e) => {
            eprintln!(
                "{what}: skipped, no graphics adapter ({e:#}); set {REQUIRE_GPU_VAR} to fail"
            );
            Ok(None)
        }
    }
}
