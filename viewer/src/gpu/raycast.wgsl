// Composition of the CPU floating-horizon raycast (Szenberg 1997, ch. 8):
// its colour and its depth — the GPU projection's depth by construction,
// eq. 5.11 — are written into the shared colour and depth targets, so
// objects drawn afterwards are hidden exactly where the terrain covers them.
// A terrain-only frame uses `fs_colour` and skips the depth upload
// (table 8.1).

@group(0) @binding(0) var colour: texture_2d<f32>;
@group(0) @binding(1) var depth: texture_2d<f32>;

@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    // One triangle covering the screen.
    let corner = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4<f32>(corner * 2.0 - 1.0, 0.0, 1.0);
}

struct WithDepth {
    @location(0) colour: vec4<f32>,
    @builtin(frag_depth) depth: f32,
};

@fragment
fn fs_colour_and_depth(@builtin(position) p: vec4<f32>) -> WithDepth {
    let pixel = vec2<i32>(p.xy);
    var out: WithDepth;
    out.colour = textureLoad(colour, pixel, 0);
    out.depth = textureLoad(depth, pixel, 0).r;
    return out;
}

@fragment
fn fs_colour(@builtin(position) p: vec4<f32>) -> @location(0) vec4<f32> {
    return textureLoad(colour, vec2<i32>(p.xy), 0);
}
