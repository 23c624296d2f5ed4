#include "trailnav/perception/terrain_features.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>

#if defined(__SSE2__)
#include <immintrin.h>
#endif

namespace trailnav::perception {

std::string_view terrain_feature_name(TerrainFeature f) noexcept {
  switch (f) {
    case TerrainFeature::max_remission: return "max remission";
    case TerrainFeature::mean_remission: return "mean remission";
    case TerrainFeature::std_remission: return "std remission";
    case TerrainFeature::roughness: return "roughness";
    case TerrainFeature::slope: return "slope";
    case TerrainFeature::area_std_remission: return "area std remission";
  }
  return "?";
}

namespace {

// Four cells at a time, one per lane: the feature is straight-line code (both
// sides of every choice are computed and the lane's side kept), so it runs
// on four-wide vectors without branches. GCC and Clang vector extensions.
using F4 = float __attribute__((vector_size(16)));
using I4 = std::int32_t __attribute__((vector_size(16)));

F4 splat(float v) noexcept { return F4{v, v, v, v}; }
F4 vsqrt(F4 x) noexcept {
#if defined(__SSE2__)
  return reinterpret_cast<F4>(_mm_sqrt_ps(reinterpret_cast<__m128>(x)));
#else
  for (int l = 0; l < 4; ++l) x[l] = std::sqrt(x[l]);
  return x;
#endif
}
F4 vabs(F4 x) noexcept { return reinterpret_cast<F4>(reinterpret_cast<I4>(x) & 0x7fffffff); }
F4 vmin(F4 a, F4 b) noexcept { return b < a ? b : a; }
F4 vmax(F4 a, F4 b) noexcept { return a < b ? b : a; }

// A symmetric 3 x 3 matrix per lane, by its upper triangle.
struct Sym3 {
  F4 a00, a01, a02, a11, a12, a22;
};

struct Vec3 {
  F4 x, y, z;
};

Vec3 cross(const Vec3& a, const Vec3& b) noexcept {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
F4 dot(const Vec3& a, const Vec3& b) noexcept { return a.x * b.x + a.y * b.y + a.z * b.z; }
Vec3 scaled(const Vec3& a, F4 s) noexcept { return {a.x * s, a.y * s, a.z * s}; }
Vec3 pick(I4 mask, const Vec3& a, const Vec3& b) noexcept {
  return {mask ? a.x : b.x, mask ? a.y : b.y, mask ? a.z : b.z};
}

// acos on [-1, 1] without a library call: sqrt(1 - x) times a degree-7
// polynomial (Abramowitz & Stegun 4.4.46, error below 2e-8 rad), mirrored for
// negative x. glibc's acosf took a third of a feature's time.
F4 fast_acos(F4 x) noexcept {
  const F4 a = vmin(splat(1.0f), vabs(x));
  F4 poly = splat(-0.0012624911f);
  for (const float c : {0.0066700901f, -0.0170881256f, 0.0308918810f, -0.0501743046f, 0.0889789874f, -0.2145988016f,
                        1.5707963050f}) {
    poly = poly * a + c;
  }
  const F4 r = vsqrt(1.0f - a) * poly;
  return x < 0.0f ? 3.14159265358979f - r : r;
}

// cos and sin of an angle in [0, pi/3] by their Taylor series up to the
// 10th / 11th power (error below 4e-9 there).
F4 short_cos(F4 t) noexcept {
  const F4 t2 = t * t;
  return 1.0f + t2 * (-1.0f / 2 + t2 * (1.0f / 24 + t2 * (-1.0f / 720 + t2 * (1.0f / 40320 + t2 * (-1.0f / 3628800)))));
}
F4 short_sin(F4 t) noexcept {
  const F4 t2 = t * t;
  return t * (1.0f + t2 * (-1.0f / 6 + t2 * (1.0f / 120 + t2 * (-1.0f / 5040 + t2 * (1.0f / 362880 + t2 * (-1.0f / 39916800))))));
}

// The eigenvalues in increasing order: the roots of the characteristic cubic
// in trigonometric form, for the matrix shifted by its mean eigenvalue m,
// A - mI = 2p cos(...): one acos, one cos and one sin, no iterations.
std::array<F4, 3> eigenvalues(const Sym3& a) noexcept {
  const F4 m = (a.a00 + a.a11 + a.a22) * (1.0f / 3.0f);
  const F4 b00 = a.a00 - m, b11 = a.a11 - m, b22 = a.a22 - m;
  F4 p2 = (b00 * b00 + b11 * b11 + b22 * b22 + 2.0f * (a.a01 * a.a01 + a.a02 * a.a02 + a.a12 * a.a12)) * (1.0f / 6.0f);
  const I4 isotropic = !(p2 > 1e-14f);  // (close to) a multiple of the identity: all three are m
  p2 = isotropic ? splat(1.0f) : p2;
  const F4 p = vsqrt(p2);
  const F4 det = b00 * (b11 * b22 - a.a12 * a.a12) - a.a01 * (a.a01 * b22 - a.a12 * a.a02) +
                 a.a02 * (a.a01 * a.a12 - b11 * a.a02);
  const F4 r = vmin(splat(1.0f), vmax(splat(-1.0f), det / (2.0f * p2 * p)));
  const F4 phi = fast_acos(r) * (1.0f / 3.0f);  // in [0, pi/3]
  const F4 cos_phi = short_cos(phi), sin_phi = short_sin(phi);
  const F4 hi = m + 2.0f * p * cos_phi;
  // cos(phi + 2 pi / 3) = -cos(phi) / 2 - sin(phi) sqrt(3) / 2
  const F4 lo = m + 2.0f * p * (-0.5f * cos_phi - 0.8660254037844386f * sin_phi);
  return {isotropic ? m : lo, isotropic ? m : 3.0f * m - lo - hi, isotropic ? m : hi};
}

// A unit vector spanning the kernel of A - lambda I, for an eigenvalue
// lambda apart from the other two: the longest cross product of two rows.
Vec3 eigenvector(const Sym3& a, F4 lambda) noexcept {
  const Vec3 r0{a.a00 - lambda, a.a01, a.a02};
  const Vec3 r1{a.a01, a.a11 - lambda, a.a12};
  const Vec3 r2{a.a02, a.a12, a.a22 - lambda};
  Vec3 best = cross(r0, r1);
  F4 best_n = dot(best, best);
  for (const Vec3& c : {cross(r0, r2), cross(r1, r2)}) {
    const F4 n = dot(c, c);
    const I4 longer = n > best_n;
    best = pick(longer, c, best);
    best_n = longer ? n : best_n;
  }
  const I4 none = !(best_n > 0.0f);
  const Vec3 unit = scaled(best, 1.0f / vsqrt(none ? splat(1.0f) : best_n));
  return pick(none, Vec3{splat(0.0f), splat(0.0f), splat(1.0f)}, unit);
}

Vec3 apply(const Sym3& a, const Vec3& v) noexcept {
  return {a.a00 * v.x + a.a01 * v.y + a.a02 * v.z, a.a01 * v.x + a.a11 * v.y + a.a12 * v.z,
          a.a02 * v.x + a.a12 * v.y + a.a22 * v.z};
}

// The eigenvector of the smallest eigenvalue when the largest one, with
// eigenvector v2, stands apart: the smallest direction of A within the plane
// across v2 (a 2 x 2 problem), so it is orthogonal to v2 even when the two
// smaller eigenvalues are nearly equal and their own kernels are ill-posed.
Vec3 smallest_across(const Sym3& a, const Vec3& v2) noexcept {
  // A unit vector across v2: v2 crossed with the axis it is least along.
  const F4 ax = vabs(v2.x), ay = vabs(v2.y), az = vabs(v2.z);
  const F4 zero = splat(0.0f);
  const I4 use_x = (ax <= ay) & (ax <= az), use_y = ~use_x & (ay <= az);
  Vec3 e1 = pick(use_x, Vec3{zero, v2.z, -v2.y}, pick(use_y, Vec3{-v2.z, zero, v2.x}, Vec3{v2.y, -v2.x, zero}));
  e1 = scaled(e1, 1.0f / vsqrt(dot(e1, e1)));
  const Vec3 e2 = cross(v2, e1);
  const Vec3 ae1 = apply(a, e1), ae2 = apply(a, e2);
  const F4 m11 = dot(e1, ae1), m12 = dot(e2, ae1), m22 = dot(e2, ae2);
  const F4 half = 0.5f * (m11 - m22);
  const F4 mu = 0.5f * (m11 + m22) - vsqrt(half * half + m12 * m12);
  // (m12, mu - m11) and (mu - m22, m12) both span the kernel; take the longer.
  const I4 second = vabs(mu - m22) + vabs(m12) > vabs(m12) + vabs(mu - m11);
  const F4 x = second ? mu - m22 : m12, y = second ? m12 : mu - m11;
  const F4 n = x * x + y * y;
  const I4 flat = !(n > 0.0f);  // isotropic across v2: any direction is the smallest
  const F4 inv = 1.0f / vsqrt(flat ? splat(1.0f) : n);
  const Vec3 v{(x * e1.x + y * e2.x) * inv, (x * e1.y + y * e2.y) * inv, (x * e1.z + y * e2.z) * inv};
  return pick(flat, e1, v);
}

}  // namespace

void compute_terrain_features(const std::array<const CellStats*, 4>& cells, std::array<FeatureVector, 4>& out) noexcept {
  // Lane l holds cell l.
  F4 n, sr, srr, sx, sy, sz, sxx, sxy, sxz, syy, syz, szz;
  for (int l = 0; l < 4; ++l) {
    const CellStats& s = *cells[static_cast<std::size_t>(l)];
    n[l] = static_cast<float>(s.n);
    sr[l] = s.sr;
    srr[l] = s.srr;
    sx[l] = s.sx;
    sy[l] = s.sy;
    sz[l] = s.sz;
    sxx[l] = s.sxx;
    sxy[l] = s.sxy;
    sxz[l] = s.sxz;
    syy[l] = s.syy;
    syz[l] = s.syz;
    szz[l] = s.szz;
  }
  const F4 inv = 1.0f / n;
  const F4 mr = sr * inv;
  const F4 var_r = vmax(splat(0.0f), srr * inv - mr * mr);
  const F4 mx = sx * inv, my = sy * inv, mz = sz * inv;
  Sym3 c{sxx * inv - mx * mx, sxy * inv - mx * my, sxz * inv - mx * mz,
         syy * inv - my * my, syz * inv - my * mz, szz * inv - mz * mz};
  // Scaled to its largest entry so the cubic's terms stay far from the float
  // range's ends; the eigenvalues are scaled back.
  const F4 scale = vmax(vmax(vmax(vabs(c.a00), vabs(c.a01)), vmax(vabs(c.a02), vabs(c.a11))),
                        vmax(vabs(c.a12), vabs(c.a22)));
  const I4 spread = scale > 0.0f;  // else all points at one spot: no surface, no roughness, no slope
  const F4 k = 1.0f / (spread ? scale : splat(1.0f));
  c = {c.a00 * k, c.a01 * k, c.a02 * k, c.a11 * k, c.a12 * k, c.a22 * k};
  const std::array<F4, 3> lambda = eigenvalues(c);
  // The smallest eigenvalue is the roughness, its eigenvector the surface
  // normal. Points along one line (a single lidar ring crossing the cell)
  // leave the normal undetermined in the plane across the line; the surface
  // then is taken to contain the line and the horizontal across it, so the
  // slope is the line's own rise: asin |v2.z|.
  const F4 roughness = spread ? vmax(splat(0.0f), lambda[0] * scale) : splat(0.0f);
  const I4 line = lambda[1] < 0.05f * lambda[2];
  const Vec3 v2 = eigenvector(c, lambda[2]);
  const I4 apart = lambda[1] - lambda[0] >= lambda[2] - lambda[1];  // the smallest stands apart
  const Vec3 normal = pick(apart, eigenvector(c, lambda[0]), smallest_across(c, v2));
  constexpr float kHalfPi = 1.5707963267948966f;
  const F4 slope_rad = line ? kHalfPi - fast_acos(vabs(v2.z)) : fast_acos(vabs(normal.z));
  constexpr float kDeg = 57.29577951308232f;
  const F4 slope = spread ? slope_rad * kDeg : splat(0.0f);
  const F4 std_r = vsqrt(var_r);
  for (int l = 0; l < 4; ++l) {
    const CellStats& s = *cells[static_cast<std::size_t>(l)];
    FeatureVector& f = out[static_cast<std::size_t>(l)];
    f[static_cast<int>(TerrainFeature::max_remission)] = s.max_r;
    f[static_cast<int>(TerrainFeature::mean_remission)] = s.r0 + mr[l];
    f[static_cast<int>(TerrainFeature::std_remission)] = std_r[l];
    f[static_cast<int>(TerrainFeature::roughness)] = roughness[l];
    f[static_cast<int>(TerrainFeature::slope)] = slope[l];
    f[static_cast<int>(TerrainFeature::area_std_remission)] = std_r[l];
  }
}

FeatureVector compute_terrain_feature(const CellStats& s) noexcept {
  std::array<FeatureVector, 4> out;
  compute_terrain_features({&s, &s, &s, &s}, out);
  return out[0];
}

}  // namespace trailnav::perception
