// Composition of the CPU floating-horizon raycast (Szenberg 1997, ch. 8):
// its colour and its depth — the GPU projection's depth by construction,
// eq. 5.11 — are written into the shared colour and depth targets, so
// objects drawn afterwards are hidden exactly where the terrain covers them.
// A terrain-only frame uses `fs_colour` and skips the depth upload
// (table 8.1).

// Both are in the raycaster's column tiles: one tile per layer.
@group(0) @binding(0) var colour: texture_2d_array<f32>;
@group(0) @binding(1) var depth: texture_2d_array<f32>;

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

// Pixel `p` of the screen: its column within its tile, its row, its tile.
struct Texel {
    at: vec2<i32>,
    tile: i32,
};

// relevo_core::horizon::TILE_COLUMNS (a test checks they agree): a
// constant power of two, so the split below is a mask and a shift.
const TILE_COLUMNS: u32 = 64u;

fn texel(p: vec4<f32>) -> Texel {
    let x = u32(p.x);
    return Texel(vec2<i32>(i32(x % TILE_COLUMNS), i32(p.y)), i32(x / TILE_COLUMNS));
}

@fragment
fn fs_colour_and_depth(@builtin(position) p: vec4<f32>) -> WithDepth {
    let t = texel(p);
    var out: WithDepth;
    out.colour = textureLoad(colour, t.at, t.tile, 0);
    out.depth = textureLoad(depth, t.at, t.tile, 0).r;
    return out;
}

@fragment
fn fs_colour(@builtin(position) p: vec4<f32>) -> @location(0) vec4<f32> {
    let t = texel(p);
    return textureLoad(colour, t.at, t.tile, 0);
}
