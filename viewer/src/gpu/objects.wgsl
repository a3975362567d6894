// Objects placed on the terrain, drawn after it with the same off-axis
// projection and depth test, so the terrain hides them exactly where it
// is in front (Szenberg 1997, ch. 8).

struct Uniforms {
    view_proj: mat4x4<f32>,
    // xyz: unit vector towards the sun; w: ambient light.
    sun: vec4<f32>,
};

@group(0) @binding(0) var<uniform> u: Uniforms;

struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) colour: vec4<f32>,
};

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) colour: vec4<f32>,
};

@vertex
fn vs_main(v: VertexIn) -> VertexOut {
    var out: VertexOut;
    out.clip = u.view_proj * vec4<f32>(v.position, 1.0);
    out.normal = v.normal;
    out.colour = v.colour;
    return out;
}

@fragment
fn fs_main(v: VertexOut, @builtin(front_facing) front: bool) -> @location(0) vec4<f32> {
    let n = select(-v.normal, v.normal, front);
    let light = u.sun.w + (1.0 - u.sun.w) * max(dot(normalize(n), u.sun.xyz), 0.0);
    return vec4<f32>(v.colour.rgb * light, 1.0);
}
