/* LD_PRELOAD shim for benchmarking Debian's python3-open3d 0.16 (bench/python/open3d_compare.py).
 *
 * That Open3D leaves the ray mask at 0 and Debian's Embree 3 is built with ray masks
 * (EMBREE_RAY_MASK): every geometry's mask is 0xFFFFFFFF, 0 & 0xFFFFFFFF is 0, so Embree skips
 * every geometry and every ray misses. This shim replaces the two stream entry points Open3D
 * calls, sets each ray's mask to 0xFFFFFFFF and forwards to Embree's own functions. The extra
 * work is one store per ray before Embree traces it.
 *
 * Build: cc -shared -fPIC -O2 embree_mask_shim.c -o libembree_mask_shim.so -ldl
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>

#include <embree3/rtcore.h>

typedef void (*Intersect1M)(RTCScene, struct RTCIntersectContext*, struct RTCRayHit*, unsigned int, size_t);
typedef void (*Occluded1M)(RTCScene, struct RTCIntersectContext*, struct RTCRay*, unsigned int, size_t);

/* Embree's own symbol: the next definition after this library, else the one in libembree3. */
static void* embreeSymbol(const char* name) {
  void* f = dlsym(RTLD_NEXT, name);
  if (!f) {
    void* lib = dlopen("libembree3.so.3", RTLD_NOW | RTLD_GLOBAL);
    if (lib) f = dlsym(lib, name);
  }
  if (!f) {
    fprintf(stderr, "embree_mask_shim: cannot find Embree's %s: %s\n", name, dlerror());
    abort();
  }
  return f;
}

void rtcIntersect1M(RTCScene scene, struct RTCIntersectContext* context, struct RTCRayHit* rayhit, unsigned int M,
                    size_t byteStride) {
  static Intersect1M real = NULL;
  if (!real) real = (Intersect1M)embreeSymbol("rtcIntersect1M");
  for (unsigned int i = 0; i < M; ++i) ((struct RTCRayHit*)((char*)rayhit + i * byteStride))->ray.mask = 0xFFFFFFFFu;
  real(scene, context, rayhit, M, byteStride);
}

void rtcOccluded1M(RTCScene scene, struct RTCIntersectContext* context, struct RTCRay* ray, unsigned int M,
                   size_t byteStride) {
  static Occluded1M real = NULL;
  if (!real) real = (Occluded1M)embreeSymbol("rtcOccluded1M");
  for (unsigned int i = 0; i < M; ++i) ((struct RTCRay*)((char*)ray + i * byteStride))->mask = 0xFFFFFFFFu;
  real(scene, context, ray, M, byteStride);
}
