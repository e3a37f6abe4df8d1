/* OpenCL's common math builtins, inlined on PoCL (programs.py puts this
 * header before every program there, and nowhere else).
 *
 * PoCL links its builtin library into a kernel after the compiler's
 * inliner has run, so every dot, fmax or sqrt stays a function call: on the
 * CPU device a third of the image kernel's own time went to calls of
 * three-instruction functions, and the kd-tree traversal spent 12% in
 * isnan, isinf, fmin and fmax (a vector's any() and select() too). Here
 * the most used ones are written inline,
 * with the builtins' results: fmin/fmax as IEEE minNum/maxNum (a NaN
 * operand loses), sqrt correctly rounded, length and normalize as the
 * plain sum of squares where it can neither overflow nor underflow and the
 * builtin (which scales) elsewhere. Each name is then defined as a macro
 * for its inline version (replacing PoCL's own macro for the library
 * function), so kernels keep calling dot, fmax, length. */
#ifndef GPUGI_POCL_BUILTINS_H
#define GPUGI_POCL_BUILTINS_H
/* helpers a hot loop calls, inlined where they are called (device/inline.h) */
#define GPUGI_HOT_INLINE inline __attribute__((always_inline))
/* only where the compiler has the elementwise builtins (Clang 14 and
 * later): an older PoCL keeps its library calls */
#if defined(__has_builtin) && __has_builtin(__builtin_elementwise_max) && __has_builtin(__builtin_elementwise_abs)

#define INLINE_OVL inline __attribute__((overloadable, always_inline))

/* fmin and fmax for a float, a vector, and a vector against a float: the
 * compiler's own builtins */
#define INLINE_MIN_MAX(name, scalar, elementwise)                                                  \
    INLINE_OVL float name(float a, float b) { return scalar(a, b); }                               \
    INLINE_OVL float2 name(float2 a, float2 b) { return elementwise(a, b); }                       \
    INLINE_OVL float3 name(float3 a, float3 b) { return elementwise(a, b); }                       \
    INLINE_OVL float4 name(float4 a, float4 b) { return elementwise(a, b); }                       \
    INLINE_OVL float2 name(float2 a, float b) { return elementwise(a, (float2)(b)); }              \
    INLINE_OVL float3 name(float3 a, float b) { return elementwise(a, (float3)(b)); }              \
    INLINE_OVL float4 name(float4 a, float b) { return elementwise(a, (float4)(b)); }
INLINE_MIN_MAX(Inline_fmin, __builtin_fminf, __builtin_elementwise_min)
INLINE_MIN_MAX(Inline_fmax, __builtin_fmaxf, __builtin_elementwise_max)

/* fabs and sqrt: the compiler's own builtins */
INLINE_OVL float Inline_fabs(float a) { return __builtin_fabsf(a); }
INLINE_OVL float2 Inline_fabs(float2 a) { return __builtin_elementwise_abs(a); }
INLINE_OVL float3 Inline_fabs(float3 a) { return __builtin_elementwise_abs(a); }
INLINE_OVL float4 Inline_fabs(float4 a) { return __builtin_elementwise_abs(a); }
INLINE_OVL float Inline_sqrt(float a) { return __builtin_sqrtf(a); }
INLINE_OVL float2 Inline_sqrt(float2 a) { return (float2)(__builtin_sqrtf(a.x), __builtin_sqrtf(a.y)); }
INLINE_OVL float3 Inline_sqrt(float3 a) {
    return (float3)(__builtin_sqrtf(a.x), __builtin_sqrtf(a.y), __builtin_sqrtf(a.z));
}

/* isnan, isinf, isfinite of a float */
INLINE_OVL int Inline_isnan(float x) { return __builtin_isnan(x); }
INLINE_OVL int Inline_isinf(float x) { return __builtin_isinf(x); }
INLINE_OVL int Inline_isfinite(float x) { return __builtin_isfinite(x); }

/* popcount of a uint and a ulong */
INLINE_OVL uint Inline_popcount(uint x) { return (uint)__builtin_popcount(x); }
INLINE_OVL ulong Inline_popcount(ulong x) { return (ulong)__builtin_popcountl(x); }

/* clamp(x, lo, hi) = fmin(fmax(x, lo), hi), and mix(x, y, a) = x + (y - x) a, as the specification defines them */
INLINE_OVL float Inline_clamp(float x, float lo, float hi) { return Inline_fmin(Inline_fmax(x, lo), hi); }
INLINE_OVL float2 Inline_clamp(float2 x, float lo, float hi) { return Inline_fmin(Inline_fmax(x, lo), hi); }
INLINE_OVL float3 Inline_clamp(float3 x, float lo, float hi) { return Inline_fmin(Inline_fmax(x, lo), hi); }
INLINE_OVL float4 Inline_clamp(float4 x, float lo, float hi) { return Inline_fmin(Inline_fmax(x, lo), hi); }
INLINE_OVL float3 Inline_clamp(float3 x, float3 lo, float3 hi) { return Inline_fmin(Inline_fmax(x, lo), hi); }
INLINE_OVL int Inline_clamp(int x, int lo, int hi) { return x < lo ? lo : (x > hi ? hi : x); }
INLINE_OVL uint Inline_clamp(uint x, uint lo, uint hi) { return x < lo ? lo : (x > hi ? hi : x); }
INLINE_OVL float Inline_mix(float x, float y, float a) { return x + (y - x) * a; }
INLINE_OVL float3 Inline_mix(float3 x, float3 y, float a) { return x + (y - x) * a; }
INLINE_OVL float3 Inline_mix(float3 x, float3 y, float3 a) { return x + (y - x) * a; }
INLINE_OVL float4 Inline_mix(float4 x, float4 y, float a) { return x + (y - x) * a; }

/* any (a lane's sign bit set) and select (each lane by the sign bit of
 * c's, a scalar by c != 0), as the specification defines them */
INLINE_OVL int Inline_any(int x) { return x < 0; }
INLINE_OVL int Inline_any(int4 m) { return (m.x | m.y | m.z | m.w) < 0; }
INLINE_OVL float Inline_select(float a, float b, int c) { return c ? b : a; }
INLINE_OVL float4 Inline_select(float4 a, float4 b, int4 c) {
    int4 take_b = c >> 31;
    return as_float4((as_int4(b) & take_b) | (as_int4(a) & ~take_b));
}

/* min, max and abs of integers (abs an unsigned result, as the
 * specification's), clz, floor, and isless of a float4 (each lane -1 where
 * a < b, 0 else, NaN lanes 0): compares and the compiler's own builtins */
INLINE_OVL int Inline_min(int a, int b) { return a < b ? a : b; }
INLINE_OVL uint Inline_min(uint a, uint b) { return a < b ? a : b; }
INLINE_OVL int3 Inline_min(int3 a, int3 b) { return __builtin_elementwise_min(a, b); }
INLINE_OVL int Inline_max(int a, int b) { return a > b ? a : b; }
INLINE_OVL uint Inline_max(uint a, uint b) { return a > b ? a : b; }
INLINE_OVL int3 Inline_max(int3 a, int3 b) { return __builtin_elementwise_max(a, b); }
INLINE_OVL int4 Inline_max(int4 a, int4 b) { return __builtin_elementwise_max(a, b); }
INLINE_OVL uint Inline_abs(int a) { return a < 0 ? 0u - (uint)a : (uint)a; }
INLINE_OVL int Inline_clz(int x) { return x ? __builtin_clz((uint)x) : 32; }
INLINE_OVL uint Inline_clz(uint x) { return x ? (uint)__builtin_clz(x) : 32u; }
INLINE_OVL float Inline_floor(float a) { return __builtin_floorf(a); }
INLINE_OVL float2 Inline_floor(float2 a) { return (float2)(__builtin_floorf(a.x), __builtin_floorf(a.y)); }
INLINE_OVL float3 Inline_floor(float3 a) {
    return (float3)(__builtin_floorf(a.x), __builtin_floorf(a.y), __builtin_floorf(a.z));
}
INLINE_OVL int4 Inline_isless(float4 a, float4 b) { return a < b; }

/* dot and cross */
INLINE_OVL float Inline_dot(float2 a, float2 b) { return a.x * b.x + a.y * b.y; }
INLINE_OVL float Inline_dot(float3 a, float3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
INLINE_OVL float Inline_dot(float4 a, float4 b) { return a.x * b.x + a.y * b.y + a.z * b.z + a.w * b.w; }
INLINE_OVL float3 Inline_cross(float3 a, float3 b) {
    return (float3)(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}

/* length and normalize: the sum of squares while it lies where no square
 * can have overflowed and the ones it drops to underflow do not count; the
 * builtin's scaled sum elsewhere (tiny, huge, zero, infinite or NaN) */
#define INLINE_SQUARES_SAFE(s) ((s) > 1e-30f && (s) < 1e30f)
INLINE_OVL float Inline_length(float2 v) {
    float s = Inline_dot(v, v);
    return INLINE_SQUARES_SAFE(s) ? __builtin_sqrtf(s) : length(v);
}
INLINE_OVL float Inline_length(float3 v) {
    float s = Inline_dot(v, v);
    return INLINE_SQUARES_SAFE(s) ? __builtin_sqrtf(s) : length(v);
}
INLINE_OVL float3 Inline_normalize(float3 v) {
    float s = Inline_dot(v, v);
    return INLINE_SQUARES_SAFE(s) ? v / __builtin_sqrtf(s) : normalize(v);
}

/* asin(s) = s + s z P(z) with z = s^2 for |x| <= 1/2, and beyond that
 * pi/2 - 2 asin(sqrt((1 - |x|) / 2)); P: a degree-4 least-maximum fit of
 * (asin(s) - s) / (s z) on z in [0, 1/4] (relative error 5e-9, so the
 * result is within the builtin's 4 ulp) */
INLINE_OVL float Inline_asin(float x) {
    float a = __builtin_fabsf(x);
    bool outer = a > 0.5f;
    float z = outer ? 0.5f * (1.0f - a) : a * a;
    float s = outer ? __builtin_sqrtf(z) : a;
    float p = s + s * z * ((((0.04216631f * z + 0.02417952f) * z + 0.04547038f) * z + 0.07495297f) * z + 0.16666752f);
    /* pi/2 split in two floats */
    float r = outer ? (1.57079637f - 2.0f * p) - 4.37113900e-8f : p;
    return __builtin_copysignf(r, x);
}

/* native_sin and native_cos (whose accuracy OpenCL leaves to the device):
 * x reduced by pi/2 (Cody and Waite's three-part constant, exact while
 * |x| < 8192), then degree-7 and degree-8 fits on [-pi/4, pi/4] (relative
 * error 4e-9 and 1e-10) chosen and signed by the quadrant; the library
 * function for larger, infinite or NaN x */
#define INLINE_TRIG_REACH 8192.0f
INLINE_OVL float Inline_trig_quadrant(float x, int *q) {
    float k = __builtin_rintf(x * 0.636619772f);
    *q = (int)k & 3;
    return ((x - k * 1.5703125f) - k * 4.83751297e-4f) - k * 7.54978995e-8f;
}
INLINE_OVL float Inline_trig_sin(float r) {
    float r2 = r * r;
    return r + r * r2 * ((-1.9515296e-4f * r2 + 8.332161e-3f) * r2 - 0.16666655f);
}
INLINE_OVL float Inline_trig_cos(float r) {
    float r2 = r * r;
    return 1.0f - 0.5f * r2 + r2 * r2 * ((2.4433157e-5f * r2 - 1.3887316e-3f) * r2 + 4.1666646e-2f);
}
INLINE_OVL float Inline_native_sin(float x) {
    if (!(__builtin_fabsf(x) < INLINE_TRIG_REACH)) return native_sin(x);
    int q;
    float r = Inline_trig_quadrant(x, &q);
    float v = (q & 1) ? Inline_trig_cos(r) : Inline_trig_sin(r);
    return (q & 2) ? -v : v;
}
INLINE_OVL float Inline_native_cos(float x) {
    if (!(__builtin_fabsf(x) < INLINE_TRIG_REACH)) return native_cos(x);
    int q;
    float r = Inline_trig_quadrant(x, &q);
    float v = (q & 1) ? Inline_trig_sin(r) : Inline_trig_cos(r);
    return ((q + 1) & 2) ? -v : v;
}

/* prefetch, which PoCL's library makes a call that does nothing: a read
 * prefetch of the first and the last value's cache lines (the kd-tree build
 * asks ahead for a straddling triangle's corners) */
#if __has_builtin(__builtin_prefetch)
INLINE_OVL void Inline_prefetch(const __global float4 *p, size_t n) {
    __builtin_prefetch(p);
    __builtin_prefetch(p + n - 1);
}
#undef prefetch
#define prefetch Inline_prefetch
#endif

#undef popcount
#define popcount Inline_popcount
#undef isnan
#define isnan Inline_isnan
#undef isinf
#define isinf Inline_isinf
#undef isfinite
#define isfinite Inline_isfinite
#undef fmin
#define fmin Inline_fmin
#undef fmax
#define fmax Inline_fmax
#undef fabs
#define fabs Inline_fabs
#undef sqrt
#define sqrt Inline_sqrt
#undef clamp
#define clamp Inline_clamp
#undef mix
#define mix Inline_mix
#undef any
#define any Inline_any
#undef select
#define select Inline_select
#undef min
#define min Inline_min
#undef max
#define max Inline_max
#undef abs
#define abs Inline_abs
#undef clz
#define clz Inline_clz
#undef floor
#define floor Inline_floor
#undef isless
#define isless Inline_isless
#undef dot
#define dot Inline_dot
#undef cross
#define cross Inline_cross
#undef length
#define length Inline_length
#undef normalize
#define normalize Inline_normalize
#undef asin
#define asin Inline_asin
#undef native_sin
#define native_sin Inline_native_sin
#undef native_cos
#define native_cos Inline_native_cos

#endif /* __has_builtin */
#endif
