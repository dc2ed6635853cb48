// The C++ baseline for dofray's packet loop: the same scene, the same rays and the same loops as
// benches/cpp/paper_rays.rs + examples/packet_loop.rs, written directly against Embree's C API.
// If dofray's FFI layer adds nothing, the two print the same checksum and about the same Mrays/s.
//
// Build and compare with benches/cpp/run.sh. By hand (Debian 12, Embree 3):
//   g++ -std=c++17 -O3 -march=native -ffp-contract=off benches/cpp/packet_loop.cpp -lembree3
// -ffp-contract=off matters: GCC would otherwise fuse a*b+c into FMAs under -march=native, which
// Rust never does, and the rays would differ in the last bit.
//
// Usage: packet_loop [REPS] [EMBREE_CONFIG]

#if !defined(EMBREE_MAJOR)
#if __has_include(<embree4/rtcore.h>)
#define EMBREE_MAJOR 4
#else
#define EMBREE_MAJOR 3
#endif
#endif

#if EMBREE_MAJOR == 4
#include <embree4/rtcore.h>
#else
#include <embree3/rtcore.h>
#endif

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <vector>

namespace {

// ---- glam's Vec3, with the same operation order --------------------------------------------

struct Vec3 {
  float x, y, z;
};
Vec3 operator+(Vec3 a, Vec3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
Vec3 operator-(Vec3 a, Vec3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
Vec3 operator*(Vec3 a, float s) { return {a.x * s, a.y * s, a.z * s}; }
float dot(Vec3 a, Vec3 b) { return (a.x * b.x) + (a.y * b.y) + (a.z * b.z); }
Vec3 cross(Vec3 a, Vec3 b) {
  return {a.y * b.z - b.y * a.z, a.z * b.x - b.z * a.x, a.x * b.y - b.x * a.y};
}
Vec3 normalize(Vec3 v) { return v * (1.0f / std::sqrt(dot(v, v))); }

// ---- src/sampler.rs ------------------------------------------------------------------------

uint64_t hash64(uint64_t x) {
  x += 0x9e3779b97f4a7c15ull;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
  return x ^ (x >> 31);
}

uint32_t reverse_bits(uint32_t x) {
  x = ((x >> 1) & 0x55555555u) | ((x & 0x55555555u) << 1);
  x = ((x >> 2) & 0x33333333u) | ((x & 0x33333333u) << 2);
  x = ((x >> 4) & 0x0f0f0f0fu) | ((x & 0x0f0f0f0fu) << 4);
  x = ((x >> 8) & 0x00ff00ffu) | ((x & 0x00ff00ffu) << 8);
  return (x >> 16) | (x << 16);
}

uint32_t sobol0(uint32_t i) { return reverse_bits(i); }

uint32_t sobol1(uint32_t i) {
  uint32_t v = 1u << 31, r = 0;
  while (i != 0) {
    if (i & 1) r ^= v;
    i >>= 1;
    v ^= v >> 1;
  }
  return r;
}

uint32_t laine_karras(uint32_t x, uint32_t seed) {
  x += seed;
  x ^= x * 0x6c50b47cu;
  x ^= x * 0xb82f1e52u;
  x ^= x * 0xc7afe638u;
  x ^= x * 0x8d22f6e6u;
  return x;
}

uint32_t owen_scramble(uint32_t x, uint32_t seed) {
  return reverse_bits(laine_karras(reverse_bits(x), seed));
}

float to_unit(uint32_t x) { return float(x >> 8) * (1.0f / float(1u << 24)); }

struct PixelSampler {
  uint32_t seed_x, seed_y;
  PixelSampler(uint64_t seed, uint64_t pixel) {
    uint64_t h = hash64(hash64(seed) ^ pixel);
    seed_x = uint32_t(h);
    seed_y = uint32_t(h >> 32);
  }
  void get(uint32_t i, float& u, float& v) const {
    u = to_unit(owen_scramble(sobol0(i), seed_x));
    v = to_unit(owen_scramble(sobol1(i), seed_y));
  }
};

// ---- src/camera/aperture.rs ----------------------------------------------------------------

constexpr float PI_F = 3.14159265358979323846f;

// sin and cos for |x| <= pi/4 by their Taylor series (aperture.rs: sin_cos_quarter).
void sin_cos_quarter(float x, float& s, float& c) {
  float x2 = x * x;
  s = x * (1.0f + x2 * (-1.0f / 6.0f +
                        x2 * (1.0f / 120.0f + x2 * (-1.0f / 5040.0f + x2 * (1.0f / 362880.0f - x2 / 39916800.0f)))));
  c = 1.0f + x2 * (-0.5f + x2 * (1.0f / 24.0f +
                                 x2 * (-1.0f / 720.0f +
                                       x2 * (1.0f / 40320.0f + x2 * (-1.0f / 3628800.0f + x2 / 479001600.0f)))));
}

// Shirley & Chiu's concentric map (the paper scene's aperture is a circle, anamorphic 1).
void concentric_disc(float u, float v, float& x, float& y) {
  float a = 2.0f * u - 1.0f, b = 2.0f * v - 1.0f;
  if (a == 0.0f && b == 0.0f) {
    x = y = 0.0f;
    return;
  }
  float s, c;
  if (std::fabs(a) > std::fabs(b)) {
    sin_cos_quarter((PI_F / 4.0f) * (b / a), s, c);
    x = a * c;
    y = a * s;
  } else {
    sin_cos_quarter((PI_F / 4.0f) * (a / b), s, c);
    x = b * s;
    y = b * c;
  }
}

// ---- src/camera/lens.rs (the thin lens) for the paper scene (src/scene/builtin.rs) -----------

constexpr uint32_t WIDTH = 640, HEIGHT = 480;
constexpr uint32_t STRIDE = 4, SPP = 16;
constexpr uint64_t SEED = 0;

Vec3 sphere_center(int i) { return {-1.6f + 0.8f * float(i), 0.5f, -1.0f + 2.5f * float(i)}; }

struct Camera {
  Vec3 eye, forward, right, up;
  float tan_half_vfov, aperture_radius, focus_distance;

  Camera() {
    eye = {0.0f, 1.2f, -6.0f};
    Vec3 look_at = {0.0f, 0.5f, 4.0f}, up_hint = {0.0f, 1.0f, 0.0f};
    forward = normalize(look_at - eye);
    right = normalize(cross(forward, up_hint));
    up = cross(right, forward);
    const float rads_per_deg = PI_F / 180.0f;  // Rust's f32::to_radians
    tan_half_vfov = std::tan(40.0f * rads_per_deg * 0.5f);
    aperture_radius = 0.2f;
    focus_distance = dot(sphere_center(3) - eye, forward);
  }

  Vec3 film_dir(float px, float py) const {
    float aspect = float(WIDTH) / float(HEIGHT);
    float sx = (2.0f * px / float(WIDTH) - 1.0f) * tan_half_vfov * aspect;
    float sy = (1.0f - 2.0f * py / float(HEIGHT)) * tan_half_vfov;
    return forward + right * sx + up * sy;
  }
};

struct Ray {
  Vec3 origin, dir;
  float tnear, tfar;
};

Ray lens_ray(const Camera& c, float px, float py, float lx, float ly) {
  Vec3 focus_point = c.eye + c.film_dir(px, py) * c.focus_distance;
  Vec3 origin = c.eye + (c.right * lx + c.up * ly) * c.aperture_radius;
  return {origin, normalize(focus_point - origin), 0.0f, std::numeric_limits<float>::infinity()};
}

std::vector<Ray> paper_rays(const Camera& cam) {
  std::vector<Ray> rays;
  for (uint32_t y = 0; y < HEIGHT; y += STRIDE)
    for (uint32_t x = 0; x < WIDTH; x += STRIDE) {
      PixelSampler sampler(SEED, uint64_t(y * WIDTH + x));
      float px = float(x) + 0.5f, py = float(y) + 0.5f;
      for (uint32_t i = 0; i < SPP; ++i) {
        float u, v, lx, ly;
        sampler.get(i, u, v);
        concentric_disc(u, v, lx, ly);
        rays.push_back(lens_ray(cam, px, py, lx, ly));
      }
    }
  return rays;
}

// FNV-1a over the bits of every ray's origin and direction (as rays_hash in paper_rays.rs).
uint64_t rays_hash(const std::vector<Ray>& rays) {
  uint64_t h = 0xcbf29ce484222325ull;
  for (const Ray& r : rays)
    for (float v : {r.origin.x, r.origin.y, r.origin.z, r.dir.x, r.dir.y, r.dir.z}) {
      uint32_t bits;
      std::memcpy(&bits, &v, 4);
      h = (h ^ uint64_t(bits)) * 0x00000100000001b3ull;
    }
  return h;
}

// ---- the scene: ground quad (geometry 0), five sphere points (geometry 1) ---------------------

void check(RTCDevice device, const char* what) {
  RTCError e = rtcGetDeviceError(device);
  if (e != RTC_ERROR_NONE) {
    std::fprintf(stderr, "Embree error %d in %s\n", int(e), what);
    std::exit(1);
  }
}

RTCScene paper_scene(RTCDevice device) {
  RTCScene scene = rtcNewScene(device);
  {
    RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
    const float cx = 0.0f, cz = 4.0f, h = 30.0f;
    auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(
        g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), 4));
    const float corners[4][2] = {{cx - h, cz - h}, {cx + h, cz - h}, {cx + h, cz + h}, {cx - h, cz + h}};
    for (int i = 0; i < 4; ++i) {
      v[3 * i + 0] = corners[i][0];
      v[3 * i + 1] = 0.0f;
      v[3 * i + 2] = corners[i][1];
    }
    auto* idx = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
        g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), 2));
    const unsigned tris[6] = {0, 2, 1, 0, 3, 2};
    std::copy(tris, tris + 6, idx);
    rtcSetGeometryBuildQuality(g, RTC_BUILD_QUALITY_MEDIUM);
    rtcCommitGeometry(g);
    rtcAttachGeometryByID(scene, g, 0);
    rtcReleaseGeometry(g);
  }
  {
    RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_SPHERE_POINT);
    auto* s = static_cast<float*>(rtcSetNewGeometryBuffer(
        g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT4, 4 * sizeof(float), 5));
    for (int i = 0; i < 5; ++i) {
      Vec3 c = sphere_center(i);
      s[4 * i + 0] = c.x;
      s[4 * i + 1] = c.y;
      s[4 * i + 2] = c.z;
      s[4 * i + 3] = 0.5f;
    }
    rtcSetGeometryBuildQuality(g, RTC_BUILD_QUALITY_MEDIUM);
    rtcCommitGeometry(g);
    rtcAttachGeometryByID(scene, g, 1);
    rtcReleaseGeometry(g);
  }
  rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_MEDIUM);
  rtcCommitScene(scene);
  check(device, "building the scene");
  return scene;
}

// ---- the two loops ---------------------------------------------------------------------------

struct Checksum {
  uint64_t hits = 0;
  double sum_t = 0.0;
  bool operator==(const Checksum& o) const { return hits == o.hits && sum_t == o.sum_t; }
};

Checksum trace_packets(RTCScene scene, const std::vector<Ray>& rays) {
  alignas(64) RTCRayHit16 rh;
  alignas(64) int valid[16];
#if EMBREE_MAJOR == 4
  RTCIntersectArguments args;
  rtcInitIntersectArguments(&args);
  args.flags = RTC_RAY_QUERY_FLAG_COHERENT;
#else
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
#endif
  Checksum sum;
  for (size_t base = 0; base < rays.size(); base += 16) {
    const size_t n = std::min<size_t>(16, rays.size() - base);
    for (size_t lane = 0; lane < 16; ++lane) valid[lane] = 0;
    for (size_t lane = 0; lane < n; ++lane) {
      const Ray& r = rays[base + lane];
      rh.ray.org_x[lane] = r.origin.x;
      rh.ray.org_y[lane] = r.origin.y;
      rh.ray.org_z[lane] = r.origin.z;
      rh.ray.dir_x[lane] = r.dir.x;
      rh.ray.dir_y[lane] = r.dir.y;
      rh.ray.dir_z[lane] = r.dir.z;
      rh.ray.tnear[lane] = r.tnear;
      rh.ray.tfar[lane] = r.tfar;
      rh.ray.time[lane] = 0.0f;
      rh.ray.mask[lane] = 0xffffffffu;
      rh.ray.id[lane] = unsigned(lane);
      rh.ray.flags[lane] = 0;
      rh.hit.geomID[lane] = RTC_INVALID_GEOMETRY_ID;
      rh.hit.primID[lane] = RTC_INVALID_GEOMETRY_ID;
      for (int l = 0; l < RTC_MAX_INSTANCE_LEVEL_COUNT; ++l) rh.hit.instID[l][lane] = RTC_INVALID_GEOMETRY_ID;
      valid[lane] = -1;
    }
#if EMBREE_MAJOR == 4
    rtcIntersect16(valid, scene, &rh, &args);
#else
    rtcIntersect16(valid, scene, &ctx, &rh);
#endif
    for (size_t lane = 0; lane < n; ++lane)
      if (rh.hit.geomID[lane] != RTC_INVALID_GEOMETRY_ID) {
        sum.hits += 1;
        sum.sum_t += double(rh.ray.tfar[lane]);
      }
  }
  return sum;
}

Checksum trace_single(RTCScene scene, const std::vector<Ray>& rays) {
  Checksum sum;
  for (const Ray& r : rays) {
    RTCRayHit rh;
    rh.ray.org_x = r.origin.x;
    rh.ray.org_y = r.origin.y;
    rh.ray.org_z = r.origin.z;
    rh.ray.tnear = r.tnear;
    rh.ray.dir_x = r.dir.x;
    rh.ray.dir_y = r.dir.y;
    rh.ray.dir_z = r.dir.z;
    rh.ray.time = 0.0f;
    rh.ray.tfar = r.tfar;
    rh.ray.mask = 0xffffffffu;
    rh.ray.id = 0;
    rh.ray.flags = 0;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
    for (int l = 0; l < RTC_MAX_INSTANCE_LEVEL_COUNT; ++l) rh.hit.instID[l] = RTC_INVALID_GEOMETRY_ID;
    // Incoherent, as dofray's Scene::intersect1 passes it.
#if EMBREE_MAJOR == 4
    RTCIntersectArguments args;
    rtcInitIntersectArguments(&args);
    args.flags = RTC_RAY_QUERY_FLAG_INCOHERENT;
    rtcIntersect1(scene, &rh, &args);
#else
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    rtcIntersect1(scene, &ctx, &rh);
#endif
    if (rh.hit.geomID != RTC_INVALID_GEOMETRY_ID) {
      sum.hits += 1;
      sum.sum_t += double(rh.ray.tfar);
    }
  }
  return sum;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

}  // namespace

int main(int argc, char** argv) {
  int reps = argc > 1 ? std::max(1, std::atoi(argv[1])) : 15;
  const char* config = argc > 2 ? argv[2] : "";
  RTCDevice device = rtcNewDevice(config);
  if (!device) {
    std::fprintf(stderr, "rtcNewDevice failed (error %d)\n", int(rtcGetDeviceError(nullptr)));
    return 1;
  }
  RTCScene scene = paper_scene(device);
  const Camera camera;
  const std::vector<Ray> rays = paper_rays(camera);
  const uint64_t hash = rays_hash(rays);

  struct Mode {
    const char* name;
    Checksum (*run)(RTCScene, const std::vector<Ray>&);
  };
  const Mode modes[] = {{"intersect16", trace_packets}, {"intersect1", trace_single}};
  // Warm up, take the checksums, then interleave the modes pass by pass so that both see the
  // same machine load (this box is shared and noisy).
  const size_t n_modes = sizeof(modes) / sizeof(modes[0]);
  std::vector<Checksum> checks;
  for (const Mode& mode : modes) checks.push_back(mode.run(scene, rays));
  std::vector<std::vector<double>> mrays(n_modes);
  for (int i = 0; i < reps; ++i)
    for (size_t m = 0; m < n_modes; ++m) {
      auto start = std::chrono::steady_clock::now();
      Checksum c = modes[m].run(scene, rays);
      double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      if (!(c == checks[m])) {
        std::fprintf(stderr, "%s: a repetition traced different hits\n", modes[m].name);
        return 1;
      }
      mrays[m].push_back(double(rays.size()) / secs / 1e6);
    }
  for (size_t m = 0; m < n_modes; ++m)
    std::printf(
        "packet_loop lang=cpp embree=%d mode=%s rays=%zu rays_hash=%016llx hits=%llu sum_t=%.6f reps=%d "
        "median_mrays=%.3f best_mrays=%.3f\n",
        EMBREE_MAJOR, modes[m].name, rays.size(), (unsigned long long)hash, (unsigned long long)checks[m].hits,
        checks[m].sum_t, reps, median(mrays[m]), *std::max_element(mrays[m].begin(), mrays[m].end()));
  check(device, "tracing");
  rtcReleaseScene(scene);
  rtcReleaseDevice(device);
  return 0;
}
