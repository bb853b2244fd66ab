// The probe-bake direction set: a spherical Fibonacci point set and uniform random rotations of it.
// NumPy twin: app/twins/directions.py.

const float DIRECTIONS_TWO_PI = 6.28318530717958648;
// Golden-ratio conjugate (sqrt(5) - 1) / 2 in 32-bit fixed point: round(2^32 * 0.618033988...).
const uint FIBONACCI_GOLDEN_FIXED = 0x9E3779B9u;

// The i-th (0 <= i < n) of n nearly uniform unit directions:
//   z = 1 - (2i + 1) / n,   phi = 2 pi fract(i * (sqrt(5) - 1) / 2).
// fract is taken in 32-bit fixed point: i * 0x9E3779B9 wraps modulo 2^32, which is exactly the
// fraction of i * 0x9E3779B9 / 2^32 for every i; its top 24 bits convert to float exactly.
// (fract(float(i) * 0.618...) in float32 would keep only 24 - log2(i) bits of the fraction.)
// 0x9E3779B9 / 2^32 is 1.2e-10 below the golden-ratio conjugate: phi drifts by 7.3e-10 * i rad.
vec3 fibonacci_direction(uint i, uint n)
{
    float fraction = float((i * FIBONACCI_GOLDEN_FIXED) >> 8u) * (1.0 / 16777216.0);
    float phi = DIRECTIONS_TWO_PI * fraction;
    float z = float(int(n) - 2 * int(i) - 1) / float(n);
    // sin(theta) = sqrt((1 - z)(1 + z)) without cancellation near the poles
    float sin_theta = sqrt(float(2u * i + 1u) * float(2u * (n - i) - 1u)) / float(n);
    return vec3(sin_theta * cos(phi), sin_theta * sin(phi), z);
}

// A rotation uniform over SO(3) from three uniforms in [0, 1) (Arvo, "Fast random rotation
// matrices", Graphics Gems III, 1992): R = -(I - 2 v v^T) R_z(2 pi u1), with the unit vector
// v = (cos(2 pi u2) sqrt(u3), sin(2 pi u2) sqrt(u3), sqrt(1 - u3)).
mat3 random_rotation(float u1, float u2, float u3)
{
    float theta = DIRECTIONS_TWO_PI * u1;
    float phi = DIRECTIONS_TWO_PI * u2;
    float r = sqrt(u3);
    vec3 v = vec3(cos(phi) * r, sin(phi) * r, sqrt(max(0.0, 1.0 - u3)));
    float c = cos(theta), s = sin(theta);
    // GLSL matrices are built from columns: R_z rotates x towards y.
    mat3 rotation_z = mat3(c, s, 0.0, -s, c, 0.0, 0.0, 0.0, 1.0);
    mat3 householder = mat3(1.0) - 2.0 * outerProduct(v, v);
    return -householder * rotation_z;
}
