#pragma once
// The checkpoint file's checksum (private to the checkpoint; its tests use it
// to forge files with a valid checksum).
#include <cstdint>
#include <span>

namespace modalwatch {

// CRC-32 (IEEE 802.3, as zlib: reflected polynomial 0xEDB88320, initial and
// final XOR 0xFFFFFFFF).
std::uint32_t crc32(std::span<const std::uint8_t> bytes);

}  // namespace modalwatch
