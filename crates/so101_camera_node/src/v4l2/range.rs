//! A control's range: one VIDIOC_QUERY_EXT_CTRL. v4l asks it inside `Device::control` without
//! returning the range, and its `query_controls` describes every control of the camera and panics
//! on types it does not know; hence this one call of its ioctl, the crate's only `unsafe`.
#![allow(unsafe_code)]

use v4l::{v4l2, v4l_sys, Device};

/// The inclusive range of control `id`, if the camera has it enabled.
pub fn of(device: &Device, id: u32) -> Option<(i64, i64)> {
    let mut query = v4l_sys::v4l2_query_ext_ctrl {
        id,
        // SAFETY: a plain C struct of integers and arrays: all zeros is a valid value.
        ..unsafe { std::mem::zeroed() }
    };
    // SAFETY: VIDIOC_QUERY_EXT_CTRL reads and writes one v4l2_query_ext_ctrl, the one passed,
    // which outlives the call.
    unsafe {
        v4l2::ioctl(
            device.handle().fd(),
            v4l2::vidioc::VIDIOC_QUERY_EXT_CTRL,
            std::ptr::addr_of_mut!(query).cast(),
        )
    }
    .ok()?;
    let disabled = query.flags & v4l_sys::V4L2_CTRL_FLAG_DISABLED != 0;
    (!disabled).then_some((query.minimum, query.maximum))
}
