//! How much memory a run may take on the adapter: Vulkan's device-local heap and, where the
//! driver has `VK_EXT_memory_budget`, the part of it this process may still allocate. wgpu has
//! no API for it (gfx-rs/wgpu#2447), so it is read through wgpu-hal's Vulkan adapter; on the
//! other APIs (Metal, DX12) it is unknown and a run is limited by the allocations alone.

/// The adapter's memory for buffers, in bytes: the driver's budget for the largest
/// device-local heap where it reports one, else that heap's size; `None` off Vulkan.
#[cfg(any(
    windows,
    target_os = "linux",
    target_os = "android",
    target_os = "freebsd"
))]
#[allow(unsafe_code)] // reading the physical device's memory properties through wgpu-hal
pub(crate) fn available(adapter: &wgpu::Adapter) -> Option<u64> {
    use ash::vk;
    // SAFETY: the hal adapter is only read (its physical device and instance handles), and
    // the guard is dropped before this function returns; nothing is created or destroyed.
    let hal = unsafe { adapter.as_hal::<wgpu::hal::api::Vulkan>() }?;
    let shared = hal.shared_instance();
    let instance = shared.raw_instance();
    let device = hal.raw_physical_device();
    // SAFETY: a physical device of the live instance it was enumerated from.
    let props = unsafe { instance.get_physical_device_memory_properties(device) };
    let heaps = props.memory_heaps_as_slice();
    let (index, heap) = heaps
        .iter()
        .enumerate()
        .filter(|(_, h)| h.flags.contains(vk::MemoryHeapFlags::DEVICE_LOCAL))
        .max_by_key(|(_, h)| h.size)?;
    // SAFETY: as above; the extension list is only read.
    let has_budget = shared.instance_api_version() >= vk::API_VERSION_1_1
        && unsafe { instance.enumerate_device_extension_properties(device) }
            .unwrap_or_default()
            .iter()
            .any(|e| e.extension_name_as_c_str() == Ok(ash::ext::memory_budget::NAME));
    if has_budget {
        let mut budget = vk::PhysicalDeviceMemoryBudgetPropertiesEXT::default();
        let mut props2 = vk::PhysicalDeviceMemoryProperties2::default().push_next(&mut budget);
        // SAFETY: Vulkan 1.1's query with the extension's structure chained, both checked
        // above; the structures outlive the call.
        unsafe { instance.get_physical_device_memory_properties2(device, &mut props2) };
        let b = budget.heap_budget[index];
        if b > 0 {
            return Some(b.min(heap.size));
        }
    }
    Some(heap.size)
}

/// Off Vulkan's platforms: unknown.
#[cfg(not(any(
    windows,
    target_os = "linux",
    target_os = "android",
    target_os = "freebsd"
)))]
pub(crate) fn available(_adapter: &wgpu::Adapter) -> Option<u64> {
    None
}
