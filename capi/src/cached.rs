//! A scene's renderer: its Embree world built at the first render and kept for later renders
//! on the same device with the same scene overrides; and a renderer's errors as C gets them.

use dofray::embree::Device;
use dofray::params::Param;
use dofray::renderer::{Renderer, RendererError};

use crate::device::{DofrayDevice, next_device_id};
use crate::scene::DofrayScene;
use crate::status::{DofrayStatus, Failure};

impl DofrayScene {
    /// The renderer on `device` (`None`: the scene's own, made at first use), built now unless
    /// the one kept was built on it with the same overrides.
    pub(crate) fn renderer(&mut self, device: Option<&DofrayDevice>) -> Result<&Renderer, Failure> {
        let device = match device {
            Some(d) => d,
            None => {
                if self.own_device.is_none() {
                    self.own_device = Some(DofrayDevice {
                        device: Device::new()?,
                        id: next_device_id(),
                    });
                }
                self.own_device.as_ref().expect("just made")
            }
        };
        let cached =
            matches!(&self.cache, Some((id, o, _)) if *id == device.id && *o == self.overrides);
        if !cached {
            // Drop the old world before building the new one: only one in memory at a time.
            self.cache = None;
            let renderer =
                Renderer::with_overrides(self.desc.clone(), self.overrides.clone(), &device.device)
                    .map_err(usage)?;
            self.cache = Some((device.id, self.overrides.clone(), renderer));
        }
        let Some((_, _, renderer)) = &self.cache else {
            unreachable!("set above")
        };
        Ok(renderer)
    }
}

/// A renderer's error as C gets it: an override or a setting named by its setter.
pub(crate) fn usage(e: RendererError) -> Failure {
    match e.param_message(Param::setter_name) {
        Some(message) => Failure::new(DofrayStatus::DOFRAY_USAGE, message),
        None => e.into(),
    }
}
