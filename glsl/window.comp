#version 460
#extension GL_GOOGLE_include_directive : require
#define WINDOW_FORMAT rgba8
#include "window.glsl"
