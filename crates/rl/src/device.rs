//! Choosing the Burn device. Only binaries and the bench/learning entry points call these;
//! the learners take a `Device` as given.

use crate::error::{Result, RlError};
use burn::tensor::Device;

/// The CPU backends this build carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum CpuBackend {
    /// burn-flex: pure-Rust, the faster one in our measurements (see `bench`), the default.
    #[default]
    Flex,
    /// burn-ndarray (deprecated upstream; only with the `ndarray` feature, off by default).
    #[cfg(feature = "ndarray")]
    NdArray,
}

impl CpuBackend {
    /// Parse `flex` or `ndarray`.
    pub fn parse(s: &str) -> Result<Self> {
        match s {
            "flex" => Ok(Self::Flex),
            #[cfg(feature = "ndarray")]
            "ndarray" => Ok(Self::NdArray),
            #[cfg(not(feature = "ndarray"))]
            "ndarray" => Err(missing("ndarray")),
            _ => Err(RlError::Config(format!("unknown CPU backend '{s}' (flex, ndarray)"))),
        }
    }

    /// Its name, as `parse` takes it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Flex => "flex",
            #[cfg(feature = "ndarray")]
            Self::NdArray => "ndarray",
        }
    }

    /// A plain (non-autodiff) device on this backend.
    pub fn device(self) -> Device {
        match self {
            Self::Flex => Device::flex(),
            #[cfg(feature = "ndarray")]
            #[allow(deprecated)] // kept selectable on purpose; see the type's doc
            Self::NdArray => Device::ndarray(),
        }
    }
}

/// The default CPU device ([`CpuBackend::default`]).
pub fn default_device() -> Device {
    CpuBackend::default().device()
}

/// The devices a learner can train on; which of them this build carries decides
/// [`DeviceChoice::device`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum DeviceChoice {
    /// burn-flex on the CPU.
    #[default]
    Flex,
    /// burn-ndarray on the CPU (the `ndarray` feature).
    NdArray,
    /// A CUDA GPU (the `cuda` feature).
    Cuda,
    /// A wgpu GPU (the `wgpu` feature).
    Wgpu,
}

impl std::str::FromStr for DeviceChoice {
    type Err = RlError;
    fn from_str(name: &str) -> Result<Self> {
        match name {
            "flex" => Ok(Self::Flex),
            "ndarray" => Ok(Self::NdArray),
            "cuda" => Ok(Self::Cuda),
            "wgpu" => Ok(Self::Wgpu),
            _ => Err(RlError::Config(format!(
                "unknown device '{name}' (flex, ndarray, cuda, wgpu)"
            ))),
        }
    }
}

impl DeviceChoice {
    /// Whether this build carries the device's backend, without opening the device: what a
    /// caller checks before it starts anything.
    pub fn check_built(self) -> Result<()> {
        let built = match self {
            Self::Flex => true,
            Self::NdArray => cfg!(feature = "ndarray"),
            Self::Cuda => cfg!(feature = "cuda"),
            Self::Wgpu => cfg!(feature = "wgpu"),
        };
        if built { Ok(()) } else { Err(missing(self.name())) }
    }

    /// Its name, as `from_str` takes it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Flex => "flex",
            Self::NdArray => "ndarray",
            Self::Cuda => "cuda",
            Self::Wgpu => "wgpu",
        }
    }

    /// The device, or why this build has none of this kind.
    pub fn device(self) -> Result<Device> {
        match self {
            Self::Flex => Ok(CpuBackend::Flex.device()),
            Self::NdArray => Ok(CpuBackend::parse("ndarray")?.device()),
            Self::Cuda => cuda(),
            Self::Wgpu => wgpu(),
        }
    }
}

/// Where a learner runs its networks' forward and backward passes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum NetPath {
    /// The host kernels (`host_gemm`, `host_cnn`) on the master weights: the CPU fast path.
    #[default]
    Host,
    /// Burn's tensors and autodiff on the learner's device, the weights mirrored there: what a
    /// GPU runs, and any CPU backend when asked for.
    Burn,
}

impl NetPath {
    /// The path a learner on `device` takes unless told otherwise: the host kernels on the CPU
    /// backends, Burn on any other device.
    pub fn for_device(device: &Device) -> Self {
        let cpu = [Some(CpuBackend::Flex.device()), cpu_ndarray()];
        if cpu.iter().flatten().any(|d| d == device) {
            Self::Host
        } else {
            Self::Burn
        }
    }

    /// Its name, as `from_str` takes it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Host => "host",
            Self::Burn => "burn",
        }
    }
}

impl std::str::FromStr for NetPath {
    type Err = RlError;
    fn from_str(name: &str) -> Result<Self> {
        match name {
            "host" => Ok(Self::Host),
            "burn" => Ok(Self::Burn),
            _ => Err(RlError::Config(format!("unknown network path '{name}' (host, burn)"))),
        }
    }
}

#[cfg(feature = "ndarray")]
fn cpu_ndarray() -> Option<Device> {
    Some(CpuBackend::NdArray.device())
}

#[cfg(not(feature = "ndarray"))]
fn cpu_ndarray() -> Option<Device> {
    None
}

/// A device by name: `flex` (CPU, always built), `ndarray` (CPU), `cuda` or `wgpu` (GPU), each
/// of the last three with the cargo feature of the same name.
pub fn device_by_name(name: &str) -> Result<Device> {
    name.parse::<DeviceChoice>()?.device()
}

fn missing(name: &str) -> RlError {
    RlError::Config(format!(
        "device '{name}' needs a build with the '{name}' feature: cargo build --release --features {name}"
    ))
}

#[cfg(feature = "cuda")]
fn cuda() -> Result<Device> {
    Ok(Device::cuda(0))
}

#[cfg(not(feature = "cuda"))]
fn cuda() -> Result<Device> {
    Err(missing("cuda"))
}

#[cfg(feature = "wgpu")]
fn wgpu() -> Result<Device> {
    let device = Device::wgpu(burn::tensor::DeviceKind::DefaultDevice);
    // cubecl opens the adapter at the first operation, and with none it panics on its device
    // thread and then on ours: one operation here turns that into an error at startup.
    let probe = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        crate::nets::to_vec(burn::tensor::Tensor::<1>::zeros([1], &device))
    }));
    match probe {
        Ok(Ok(_)) => Ok(device),
        Ok(Err(e)) => Err(e),
        Err(_) => Err(RlError::Config(
            "device 'wgpu': no usable adapter (the panic above says why; \
             CUBECL_WGPU_DEFAULT_DEVICE picks one, e.g. 'DiscreteGpu(0)')"
                .into(),
        )),
    }
}

#[cfg(not(feature = "wgpu"))]
fn wgpu() -> Result<Device> {
    Err(missing("wgpu"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn devices_by_name() {
        assert!(device_by_name("flex").is_ok());
        #[cfg(feature = "ndarray")]
        assert!(device_by_name("ndarray").is_ok());
        #[cfg(not(feature = "ndarray"))]
        {
            let e = device_by_name("ndarray").unwrap_err().to_string();
            assert!(e.contains("--features ndarray"), "{e}");
            let e = DeviceChoice::NdArray.check_built().unwrap_err().to_string();
            assert!(e.contains("--features ndarray"), "{e}");
        }
        assert!(DeviceChoice::Flex.check_built().is_ok());
        let e = device_by_name("tpu").unwrap_err().to_string();
        assert!(e.contains("tpu") && e.contains("flex"), "{e}");
        assert_eq!(NetPath::for_device(&default_device()), NetPath::Host);
        assert_eq!(NetPath::for_device(&default_device().autodiff()), NetPath::Host);
        assert_eq!("burn".parse::<NetPath>().unwrap(), NetPath::Burn);
        assert!("gpu".parse::<NetPath>().unwrap_err().to_string().contains("host, burn"));
        #[cfg(not(feature = "cuda"))]
        assert!(
            device_by_name("cuda")
                .unwrap_err()
                .to_string()
                .contains("--features cuda")
        );
    }
}
