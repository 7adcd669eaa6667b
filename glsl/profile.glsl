// Radial reflectance profiles on the device: the same functions as src/physics/profile.rs and
// src/physics/dipole.rs (Profile::rd_and_laplacian, rd_cell_mean, cumulative, disc_mean), in
// single precision, for the re-weighting of the operators (reweigh.comp).
//
// The including shader declares `PROFILE_BINDING` before the include.

#ifndef PROFILE_GLSL
#define PROFILE_GLSL

#include "numeric.glsl"

const float PI = 3.14159265358979;
// Radii of the half-space table (src/physics/profile.rs, table_radii()).
const int TABLE = 48;

struct Channel {
    // x: 0 for the dipole, 1 for the table; y: sigma_t (table).
    vec4 head;
    // albedo, sigma_tr, z_r, z_v (dipole).
    vec4 dipole;
    // The table's optical radii, cumulative fractions, annulus centres and mean values
    // (fields RADII, CUMULATIVE, CENTRES, VALUES), four to a vec4.
    vec4 table[4][TABLE / 4];
};

const int RADII = 0;
const int CUMULATIVE = 1;
const int CENTRES = 2;
const int VALUES = 3;

layout(set = 0, binding = PROFILE_BINDING, std140) uniform Profiles {
    Channel channel[3];
} profiles;

// Entry j of channel c's table `field`.
float at(int c, int field, int j) {
    return profiles.channel[c].table[field][j >> 2][j & 3];
}

// The first entry of channel c's table `field` (increasing) that is not below x; TABLE if
// none (partition_point).
int first_not_below(int c, int field, float x) {
    int lo = 0;
    int hi = TABLE;
    while (lo < hi) {
        int mid = (lo + hi) >> 1;
        if (at(c, field, mid) < x) {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    return lo;
}

// Dipole: R_d and its plane Laplacian (Dipole::rd_derivatives, rd_and_laplacian).
vec2 dipole_rd_laplacian(vec4 d, float r) {
    float s = d.y;
    float k = d.x / (4.0 * PI);
    vec3 sum = vec3(0.0);
    for (int i = 0; i < 2; i++) {
        float z = i == 0 ? d.z : d.w;
        float dd = sqrt(r * r + z * z);
        float g = (s * dd + 1.0) * exp(-s * dd) / (dd * dd * dd);
        float l = -s + s / (s * dd + 1.0) - 3.0 / dd;
        float g1 = g * l;
        float g2 = g1 * l + g * (-s * s / ((s * dd + 1.0) * (s * dd + 1.0)) + 3.0 / (dd * dd));
        float f1 = g1 * r / dd;
        float f2 = g2 * r * r / (dd * dd) + g1 * (1.0 / dd - r * r / (dd * dd * dd));
        sum += z * vec3(g, f1, f2);
    }
    sum *= k;
    float lap = r > 0.0 ? sum.z + sum.y / r : 2.0 * sum.z;
    return vec2(sum.x, lap);
}

// Dipole::cumulative, in its cancellation-free form.
float dipole_cumulative(vec4 d, float rho) {
    float s = d.y;
    float acc = 0.0;
    for (int i = 0; i < 2; i++) {
        float z = i == 0 ? d.z : d.w;
        float dd = sqrt(rho * rho + z * z);
        float delta = rho * rho / (dd + z);
        acc += exp(-s * z) * (one_minus_exp(s * delta) + exp(-s * delta) * delta / dd);
    }
    return 0.5 * d.x * acc;
}

// Table: the profile in optical units and its log-log slope (Tabulated::optical).
vec2 table_optical(int c, float x) {
    if (x <= at(c, CENTRES, 0)) {
        return vec2(at(c, VALUES, 0), 0.0);
    }
    int j = first_not_below(c, CENTRES, x);
    if (j >= TABLE) {
        return vec2(0.0);
    }
    float ca = at(c, CENTRES, j - 1);
    float cb = at(c, CENTRES, j);
    float a = at(c, VALUES, j - 1);
    float b = at(c, VALUES, j);
    if (a <= 0.0 || b <= 0.0) {
        float t = (x - ca) / (cb - ca);
        return vec2((1.0 - t) * a + t * b, 0.0);
    }
    float slope = log(b / a) / log(cb / ca);
    return vec2(a * pow(x / ca, slope), slope);
}

float table_cumulative(int c, float rho) {
    float x = rho * profiles.channel[c].head.y;
    float r0 = at(c, RADII, 0);
    if (x <= r0) {
        return at(c, CUMULATIVE, 0) * (x / r0) * (x / r0);
    }
    int j = first_not_below(c, RADII, x);
    if (j >= TABLE) {
        return at(c, CUMULATIVE, TABLE - 1);
    }
    float ra = at(c, RADII, j - 1);
    float rb = at(c, RADII, j);
    float t = (x * x - ra * ra) / (rb * rb - ra * ra);
    float ca = at(c, CUMULATIVE, j - 1);
    return ca + t * (at(c, CUMULATIVE, j) - ca);
}

// R and its plane Laplacian of channel c at r (mm).
vec2 rd_laplacian(int c, float r) {
    if (profiles.channel[c].head.x == 0.0) {
        return dipole_rd_laplacian(profiles.channel[c].dipole, r);
    }
    float st = profiles.channel[c].head.y;
    vec2 vk = table_optical(c, r * st);
    float f = vk.x * st * st;
    return vec2(f, r > 0.0 ? vk.y * vk.y * f / (r * r) : 0.0);
}

// R's mean over a cell centred at r to second order, clamped at zero (Profile::rd_cell_mean).
vec3 rd_cell_mean(float r, float s) {
    vec3 out_ = vec3(0.0);
    for (int c = 0; c < 3; c++) {
        vec2 fl = rd_laplacian(c, r);
        out_[c] = max(fl.x + s * fl.y, 0.0);
    }
    return out_;
}

// The mean of R over a disc of radius rho about the entry point (Profile::disc_mean).
vec3 disc_mean(float rho) {
    vec3 out_ = vec3(0.0);
    for (int c = 0; c < 3; c++) {
        if (rho <= 0.0) {
            out_[c] = rd_laplacian(c, 0.0).x;
        } else if (profiles.channel[c].head.x == 0.0) {
            out_[c] = dipole_cumulative(profiles.channel[c].dipole, rho) / (PI * rho * rho);
        } else {
            out_[c] = table_cumulative(c, rho) / (PI * rho * rho);
        }
    }
    return out_;
}

#endif
