#version 460
#extension GL_GOOGLE_include_directive : require
#define WINDOW_FORMAT rgba16f
#define LINEAR_OUT
#include "window.glsl"
