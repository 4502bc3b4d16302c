#pragma once
// Octahedral unit-vector encoding in 8+8 bits (Meyer et al. 2010; Cigolle et al. 2014).
//
// A unit vector is projected onto the octahedron |x|+|y|+|z| = 1, the lower half folded over
// the upper, and the square [-1,1]^2 quantized to 8 bits per axis. The *precise* encoder tries
// the four quantized neighbours of the projected point and keeps the one whose decoded vector
// is closest in angle, which lowers the worst-case error from about 1.2 to about 0.94 degrees.
//
// The 16-bit code holds u in the low byte and v in the high byte. oct_decode() is the exact CPU
// mirror of shaders/catp_decode.glsl (same operations in the same order, float32).
#include <cstddef>
#include <cstdint>

namespace catpaq {

// Encodes a unit vector (need not be exactly unit length; zero vectors map to +z).
uint16_t oct_encode_precise(float x, float y, float z);
// oct_encode_precise of count vectors at once, xyz[3i..3i+2] to codes[i]: the same codes for
// every input, several vectors at a time (for the point encoder's nodes).
void oct_encode_precise_batch(const float* xyz, size_t count, uint16_t* codes);
// Fast encoder: nearest quantized point, no search (used where speed matters more).
uint16_t oct_encode_fast(float x, float y, float z);
// Decodes to a unit vector in out[3].
void oct_decode(uint16_t code, float out[3]);

}  // namespace catpaq
