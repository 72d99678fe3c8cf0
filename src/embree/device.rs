//! The Embree device: one per process, shared by reference count.
use super::error::{error_name, EmbreeError};
use super::isa::Isa;
use super::sys;
use std::ffi::{c_char, c_void, CStr, CString};
use std::sync::Arc;

/// A ref-counted Embree device. Cloning shares the device; it is released with the last clone
/// (and after every scene made from it, which each hold a clone).
#[derive(Clone)]
pub struct Device {
    inner: Arc<DeviceHandle>,
}

struct DeviceHandle {
    raw: sys::RTCDevice,
    /// The kernel family Embree runs: the cap asked for, or the widest this CPU has.
    isa: Isa,
    /// The library's version as it reports it (`rtcGetDeviceProperty`), e.g. `4.4.0`.
    version: Version,
}

/// An Embree library version.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct Version {
    pub major: u32,
    pub minor: u32,
    pub patch: u32,
}

impl std::fmt::Display for Version {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}.{}.{}", self.major, self.minor, self.patch)
    }
}

/// The version of the headers the bindings were generated from.
pub const HEADER_VERSION: Version =
    Version { major: sys::RTC_VERSION_MAJOR, minor: sys::RTC_VERSION_MINOR, patch: sys::RTC_VERSION_PATCH };

// SAFETY: Embree devices are thread-safe: the API may be called on one device from any thread
// (Embree API docs, "Thread Safety"). The handle is only released in `Drop`, once.
unsafe impl Send for DeviceHandle {}
// SAFETY: see `Send`; shared access only calls thread-safe Embree functions.
unsafe impl Sync for DeviceHandle {}

impl Drop for DeviceHandle {
    fn drop(&mut self) {
        // SAFETY: `raw` came from a successful `rtcNewDevice` and is released exactly once here;
        // every scene holds a `Device` clone, so none outlives it.
        unsafe { sys::rtcReleaseDevice(self.raw) }
    }
}

/// Embree calls this for every error on the device; it is routed to `tracing`.
unsafe extern "C" fn log_device_error(_user: *mut c_void, code: sys::RTCError, message: *const c_char) {
    let text = if message.is_null() {
        String::new()
    } else {
        // SAFETY: Embree passes a NUL-terminated C string valid for the duration of the call.
        unsafe { CStr::from_ptr(message) }.to_string_lossy().into_owned()
    };
    tracing::error!(target: "relume::embree", code = error_name(code), "{text}");
}

impl Device {
    /// Creates a device whose build threads match `threads` (the rayon pool size); `0` lets
    /// Embree use every core.
    pub fn new(threads: usize) -> Result<Device, EmbreeError> {
        Self::with_isa(threads, None)
    }

    /// As [`Device::new`], with Embree's kernels capped at `max_isa` (`None`: the widest this
    /// CPU supports). A family the CPU cannot run is refused rather than silently narrowed.
    pub fn with_isa(threads: usize, max_isa: Option<Isa>) -> Result<Device, EmbreeError> {
        let mut config = format!("threads={threads},set_affinity=0,verbose=0");
        if let Some(isa) = max_isa {
            if !isa.supported_by_cpu() {
                let has: Vec<&str> = Isa::supported().iter().map(|i| i.name()).collect();
                return Err(EmbreeError::Device {
                    code: "RTC_ERROR_UNSUPPORTED_CPU",
                    context: format!("this CPU cannot run Embree's {isa} kernels (it has {})", has.join(", ")),
                });
            }
            config.push_str(&format!(",max_isa={isa}"));
        }
        Self::with_config(&config)
    }

    /// Creates a device from an Embree configuration string (see `rtcNewDevice`).
    pub fn with_config(config: &str) -> Result<Device, EmbreeError> {
        let config_c = CString::new(config).map_err(|_| EmbreeError::Device {
            code: "RTC_ERROR_INVALID_ARGUMENT",
            context: "device configuration contains a NUL byte".into(),
        })?;
        // SAFETY: `config_c` is a valid NUL-terminated string that outlives the call.
        let raw = unsafe { sys::rtcNewDevice(config_c.as_ptr()) };
        if raw.is_null() {
            // SAFETY: a null device asks for the error of the last failed device creation.
            let code = unsafe { sys::rtcGetDeviceError(std::ptr::null_mut()) };
            return Err(EmbreeError::Device { code: error_name(code), context: format!("rtcNewDevice(\"{config}\")") });
        }
        // SAFETY: `raw` is a live device; the callback is a plain extern fn with no user data,
        // valid for the whole program.
        unsafe { sys::rtcSetDeviceErrorFunction(raw, Some(log_device_error), std::ptr::null_mut()) };
        let version = library_version(raw);
        if version.major != HEADER_VERSION.major || version.minor < HEADER_VERSION.minor {
            // SAFETY: `raw` is live and released once, here, since no handle owns it yet.
            unsafe { sys::rtcReleaseDevice(raw) };
            return Err(EmbreeError::LibraryVersion {
                found: version.to_string(),
                headers: HEADER_VERSION.to_string(),
            });
        }
        let widest = Isa::supported().last().copied().unwrap_or(Isa::Sse2);
        let isa = config
            .split(',')
            .filter_map(|kv| kv.trim().strip_prefix("max_isa=").or_else(|| kv.trim().strip_prefix("isa=")))
            .find_map(|name| name.parse::<Isa>().ok())
            .map_or(widest, |cap| cap.min(widest));
        Ok(Device { inner: Arc::new(DeviceHandle { raw, isa, version }) })
    }

    /// The kernel family this device's queries run.
    pub fn isa(&self) -> Isa {
        self.inner.isa
    }

    /// The version of the Embree library this device runs on.
    pub fn version(&self) -> Version {
        self.inner.version
    }

    pub(crate) fn raw(&self) -> sys::RTCDevice {
        self.inner.raw
    }

    /// Returns `Err` if Embree recorded an error on this device since the last check.
    pub(crate) fn check(&self, context: impl FnOnce() -> String) -> Result<(), EmbreeError> {
        // SAFETY: `raw` is a live device handle.
        let code = unsafe { sys::rtcGetDeviceError(self.raw()) };
        if code == sys::RTC_ERROR_NONE {
            Ok(())
        } else {
            Err(EmbreeError::Device { code: error_name(code), context: context() })
        }
    }
}

/// The library's version, from `rtcGetDeviceProperty(3)`.
fn library_version(raw: sys::RTCDevice) -> Version {
    // SAFETY: `raw` is a live device; the version properties take no arguments and only read.
    let property = |p| unsafe { sys::rtcGetDeviceProperty(raw, p) }.max(0) as u32;
    Version {
        major: property(sys::RTC_DEVICE_PROPERTY_VERSION_MAJOR),
        minor: property(sys::RTC_DEVICE_PROPERTY_VERSION_MINOR),
        patch: property(sys::RTC_DEVICE_PROPERTY_VERSION_PATCH),
    }
}

impl std::fmt::Debug for Device {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Device")
            .field("isa", &self.inner.isa)
            .field("version", &self.inner.version)
            .field("holders", &Arc::strong_count(&self.inner))
            .finish()
    }
}
