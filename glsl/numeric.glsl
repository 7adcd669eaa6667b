// Small numeric helpers shared by the shaders, in forms without cancellation near 0.
#ifndef NUMERIC_GLSL
#define NUMERIC_GLSL

// 1 - e^(-x) for x >= 0, without cancellation near 0 (expm1).
float one_minus_exp(float x) {
    return x < 1e-2 ? x * (1.0 - 0.5 * x * (1.0 - x / 3.0 * (1.0 - 0.25 * x))) : 1.0 - exp(-x);
}

// The same per channel.
vec3 one_minus_exp(vec3 x) {
    return vec3(one_minus_exp(x.r), one_minus_exp(x.g), one_minus_exp(x.b));
}

#endif
