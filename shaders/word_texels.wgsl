// Words laid out as rows of Rgba32Uint texels (four words a texel, TEXELS_PER_ROW texels a row, in buffer order),
// prepended to the compute passes that read them: a software rasteriser (lavapipe) fetches a texel for all its
// lanes with gathers, where it loads a storage buffer's words lane by lane through the stack whenever the
// lanes' indices may differ. Made by `word_texels` in crates/flare_core/src/render/buffers.rs; must be kept in
// sync with `TEXELS_PER_ROW` there.
const TEXELS_PER_ROW: u32 = 2048u;

fn texel_at(words: texture_2d<u32>, i: u32) -> vec4<u32> {
    return textureLoad(words, vec2<u32>(i % TEXELS_PER_ROW, i / TEXELS_PER_ROW), 0);
}
