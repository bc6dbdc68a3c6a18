"""list_devices of Open3D's test helpers (python/test/open3d_test.py): duplex has the CPU only."""
import open3d_shim


def list_devices(enable_cuda=True, enable_sycl=False, also_sycl_cpu=True):
    return [open3d_shim.Device("CPU:0")]
