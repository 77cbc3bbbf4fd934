// The descriptor set of shadowtile's own kernels (evaluate.comp, shadow_pass.comp): the
// pool, the page table, inputs, outputs and feedback as word arrays (gpu/GPU_LAYOUT.md).
#extension GL_GOOGLE_include_directive : require
#include "st_layout.h"

layout(local_size_x = 64) in;
layout(std430, set = 0, binding = 0) readonly buffer StPool { uint st_pool_words[]; };
layout(std430, set = 0, binding = 0) readonly buffer StPoolQuads { uvec4 st_pool_quads[]; };  // the same pool
layout(std430, set = 0, binding = 1) readonly buffer StPage { uint st_page_words[]; };
layout(std430, set = 0, binding = 2) readonly buffer StInput { uint st_input_words[]; };
layout(std430, set = 0, binding = 3) readonly buffer StNormals { uint st_normal_words[]; };
layout(std430, set = 0, binding = 4) writeonly buffer StOutput { float st_output[]; };
layout(std430, set = 0, binding = 5) coherent buffer StFeedback { uint st_fb_words[]; };
layout(push_constant) uniform StPush { uint w[kPcWords]; } st_pc;

#define ST_POOL(i) st_pool_words[i]
#define ST_POOL4(q) st_pool_quads[q]
#define ST_PAGE(i) st_page_words[i]
#define ST_FB(i) st_fb_words[i]
#include "st_eval.glsl"
