// OpenVDB mask stack writer (OpenVDB 10: io::Archive, Tree::touchLeaf/addTile, math::Transform).
// Built into the OpenVDB module (io/masks/vdb_module.h), not into toposlice_io.
#include "io/masks/vdb_writer.h"
#include "io/masks/vdb_module.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <exception>
#include <fstream>
#include <optional>
#include <string>
#include <type_traits>

#include <libdeflate.h>

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wconversion"
#pragma GCC diagnostic ignored "-Wshadow"
#pragma GCC diagnostic ignored "-Wold-style-cast"
#include <openvdb/io/Archive.h>
#include <openvdb/io/File.h>
#include <openvdb/io/GridDescriptor.h>
#include <openvdb/io/io.h>
#include <openvdb/openvdb.h>
#pragma GCC diagnostic pop

#include "io/errors.h"
#include "io/output_file.h"

namespace toposlice {
namespace {

constexpr uint32_t kBandLayers = 8;  // leaf node depth

// The file's UUID from its content: every layer's encoded blocks (their CRC-32 and size, in layer order)
// folded into two 64-bit lanes, written as a UUID of version 8 (RFC 9562: custom). The same job gives
// the same UUID and the same bytes; another content, another UUID (unless its layers' checksums collide).
class ContentId {
 public:
  void add(uint32_t crc, uint64_t size) {
    const uint64_t word = uint64_t{crc} << 32 ^ size;
    a_ = mix(a_ ^ word);
    b_ = mix(b_ + word + 0x9E3779B97F4A7C15ull);
  }
  std::string uuid() const {
    const uint64_t hi = (a_ & ~0xF000ull) | 0x8000ull;        // version 8
    const uint64_t lo = (b_ & ~(3ull << 62)) | (2ull << 62);  // variant 10
    char text[37];
    std::snprintf(text, sizeof text, "%08x-%04x-%04x-%04x-%012llx", static_cast<unsigned>(hi >> 32),
                  static_cast<unsigned>(hi >> 16 & 0xFFFF), static_cast<unsigned>(hi & 0xFFFF),
                  static_cast<unsigned>(lo >> 48), static_cast<unsigned long long>(lo & 0xFFFFFFFFFFFFull));
    return text;
  }

 private:
  static uint64_t mix(uint64_t x) {  // splitmix64's finalizer
    x ^= x >> 30;
    x *= 0xBF58476D1CE4E5B9ull;
    x ^= x >> 27;
    x *= 0x94D049BB133111EBull;
    return x ^ (x >> 31);
  }
  uint64_t a_ = 0x746F706F736C6963ull, b_ = 0x65766462ull;
};

// A .vdb file written one grid at a time: the layout of io::File::write (header, file metadata, grid
// count, then each grid with its descriptor and offsets), built from io::Archive's protected pieces. The
// grid count is written as 0 and patched by close().
class SlabArchive : public openvdb::io::Archive {
 public:
  static constexpr std::streamoff kUuidOffset = 8 + 4 + 2 * 4 + 1;  // magic, versions, offsets flag
  static constexpr std::streamsize kUuidLength = 36;

  SlabArchive(const std::filesystem::path& path, const openvdb::MetaMap& fileMeta) {
    // The OutputFile's temporary, created empty: opened without truncation, which on ext4 would write the
    // whole file back as it is closed (auto_da_alloc; see openZipOnTemporary).
    os_.open(path, std::ios_base::in | std::ios_base::out | std::ios_base::binary);
    if (!os_) throw openvdb::IoError("could not open " + path.string() + " for writing");
    streamMeta_ = std::make_shared<openvdb::io::StreamMetadata>();
    openvdb::io::setStreamMetadataPtr(os_, streamMeta_, /*transfer=*/false);
    openvdb::io::setDataCompression(os_, compression());
    openvdb::io::setWriteGridStatsMetadata(os_, isGridStatsMetadataEnabled());
    writeHeader(os_, /*seekable=*/true);
    // io::Archive writes a random UUID into the header (after the magic number, the file and library
    // versions and the offsets flag); close() replaces it with one derived from the content, so the
    // same job gives the same bytes. Checked here, so that a different header layout fails loudly.
    char uuid[kUuidLength];
    const std::streampos headerEnd = os_.tellp();
    os_.seekg(kUuidOffset);
    os_.read(uuid, kUuidLength);
    if (!os_ || headerEnd != kUuidOffset + kUuidLength || uuid[8] != '-' || uuid[13] != '-' ||
        uuid[18] != '-' || uuid[23] != '-')
      throw openvdb::IoError("unexpected VDB header layout: no UUID at byte " + std::to_string(kUuidOffset));
    os_.seekp(headerEnd);
    fileMeta.writeMeta(os_);
    countPos_ = os_.tellp();
    const int32_t zero = 0;
    os_.write(reinterpret_cast<const char*>(&zero), sizeof zero);
  }

  void writeSlab(const openvdb::GridBase::ConstPtr& grid) {
    openvdb::io::GridDescriptor descriptor(grid->getName(), grid->type(), grid->saveFloatAsHalf());
    writeGrid(descriptor, grid, os_, /*seekable=*/true);
    openvdb::io::setDataCompression(os_, compression());  // writeGrid may narrow it for one grid
    ++count_;
    if (!os_) throw openvdb::IoError("write failed");
  }

  // Patches the grid count and writes `uuid` (36 characters, 8-4-4-4-12) over the random one.
  void close(const std::string& uuid) {
    const std::streampos end = os_.tellp();
    os_.seekp(countPos_);
    os_.write(reinterpret_cast<const char*>(&count_), sizeof count_);
    os_.seekp(kUuidOffset);
    os_.write(uuid.data(), kUuidLength);
    os_.seekp(end);
    os_.close();
    if (!os_) throw openvdb::IoError("write failed");
  }

 private:
  std::fstream os_;
  openvdb::io::StreamMetadata::Ptr streamMeta_;  // must outlive every write to os_
  std::streampos countPos_{};
  int32_t count_ = 0;
};

std::string slabName(uint32_t firstLayer) {
  std::string digits = std::to_string(firstLayer);
  if (digits.size() < 5) digits.insert(0, 5 - digits.size(), '0');
  return "mask_" + digits;
}

// kSpread[b]: bit y of b moved to bit 8 y (a column of a block, bits by row, spread to one bit per row
// of a leaf word, whose bits are y * 8 + z).
constexpr std::array<uint64_t, 256> makeSpread() {
  std::array<uint64_t, 256> table{};
  for (uint32_t b = 0; b < 256; ++b)
    for (uint32_t y = 0; y < 8; ++y)
      if (b & (1u << y)) table[b] |= uint64_t{1} << (8 * y);
  return table;
}
constexpr std::array<uint64_t, 256> kSpread = makeSpread();

// One bit per byte: bit 8 x of the result is set when byte x of `w` is non-zero.
uint64_t nonZeroBytes(uint64_t w) {
  constexpr uint64_t low7 = 0x7F7F7F7F7F7F7F7Full;
  return ((((w & low7) + low7) | w) >> 7) & 0x0101010101010101ull;
}

// Encoded layer (encodeLayer -> writeEncodedLayer): for every 8 x 8 pixel block with a lit pixel, in
// block order (row of blocks by row of blocks from the bottom, left to right), a record
//   uint32 block index (by * blocksX + bx), uint64 lit columns (byte x: bit y set when pixel (x, y) of
//   the block is lit), and for anti-aliased jobs 64 pixel values (row y, then column x).
// Pixels past the image's right or top edge count as dark.
template <class GridT>
class VdbSink final : public EncodingMaskSink {
  using TreeT = typename GridT::TreeType;
  using LeafT = typename TreeT::LeafNodeType;
  using ValueT = typename GridT::ValueType;
  static constexpr bool kIsMask = std::is_same_v<ValueT, bool>;
  static constexpr std::size_t kLeafBytes = sizeof(LeafT) + (kIsMask ? 0 : LeafT::SIZE * sizeof(ValueT));
  static constexpr std::size_t kRecordBytes = 4 + 8 + (kIsMask ? 0 : 64);

 public:
  VdbSink(const std::filesystem::path& path, const MaskJob& job, bool overwrite)
      : file_(path, overwrite),
        job_(job),
        blocksX_((job.grid.width + 7) / 8),
        blocksY_((job.grid.height + 7) / 8) {
    openvdb::initialize();
    for (int v = 0; v < 256; ++v) {
      if constexpr (kIsMask) {
        toValue_[v] = v != 0;
      } else {
        toValue_[v] = static_cast<float>(v) / 255.0f;
      }
    }
    grid_ = GridT::create();
    openvdb::MetaMap fileMeta;
    fileMeta.insertMeta("creator", openvdb::StringMetadata(std::string(kSoftwareName)));  // checkReplaceable
    fileMeta.insertMeta("layer_count", openvdb::Int32Metadata(static_cast<int32_t>(job.layerCount)));
    fileMeta.insertMeta("layer_height", openvdb::DoubleMetadata(job.layerHeight));
    fileMeta.insertMeta("pixel_size", openvdb::DoubleMetadata(job.grid.pixel));
    fileMeta.insertMeta("layout", openvdb::StringMetadata(job.vdbSlabs ? "slabs" : "single"));
    if (job.vdbSlabs)
      fileMeta.insertMeta("slab_layers", openvdb::Int32Metadata(static_cast<int32_t>(kVdbSlabLayers)));
    for (const auto& [key, value] : job.settings)  // the printer and material settings (mask_sink.h)
      fileMeta.insertMeta("toposlice:" + key, openvdb::StringMetadata(value));
    try {
      archive_.emplace(file_.tempPath(), fileMeta);  // writes through its own handle; file_ renames it
    } catch (const std::exception& e) {
      const int err = errno;
      throw OutputError(path.string() +
                        ": cannot write: " + writeFailureReason(file_.tempPath(), err, e.what()));
    }
  }

  // The layer's lit 8 x 8 blocks (see "Encoded layer" above); thread-safe.
  void encodeLayer(uint32_t /*index*/, double /*z*/, const MaskImage& mask, EncodedMaskLayer& encoded,
                   MaskEncodeScratch& /*scratch*/) const override {
    std::vector<uint8_t>& out = encoded.bytes;
    out.clear();
    const uint32_t width = job_.grid.width, height = job_.grid.height;
    if (mask.width != width || mask.height != height || mask.pixels.size() != size_t{width} * height) {
      out.push_back(0);  // not a whole number of records: writeEncodedLayer reports the size mismatch
      return;
    }
    const bool extents = mask.hasExtents();
    for (uint32_t by = 0; by < blocksY_; ++by) {
      const uint32_t y0 = by * 8, ny = std::min(8u, height - y0);
      uint32_t lo = 0, hi = width;  // columns that may hold lit pixels in these rows
      if (extents) {
        lo = width;
        hi = 0;
        for (uint32_t y = y0; y < y0 + ny; ++y) {
          if (mask.litBegin[y] >= mask.litEnd[y]) continue;
          lo = std::min(lo, mask.litBegin[y]);
          hi = std::max(hi, mask.litEnd[y]);
        }
        if (lo >= hi) continue;
      }
      for (uint32_t bx = lo / 8; bx < (hi + 7) / 8; ++bx) {
        const uint32_t x0 = bx * 8, nx = std::min(8u, width - x0);
        uint64_t rows[8] = {};
        for (uint32_t y = 0; y < ny; ++y) {
          const uint8_t* src = mask.pixels.data() + size_t{y0 + y} * width + x0;
          if (nx == 8) {
            std::memcpy(&rows[y], src, 8);
          } else {
            std::memcpy(&rows[y], src, nx);
          }
        }
        uint64_t columns = 0;
        for (uint32_t y = 0; y < 8; ++y) columns |= nonZeroBytes(rows[y]) << y;
        if (columns == 0) continue;
        const uint32_t index = by * blocksX_ + bx;
        const size_t at = out.size();
        out.resize(at + kRecordBytes);
        std::memcpy(out.data() + at, &index, 4);
        std::memcpy(out.data() + at + 4, &columns, 8);
        if constexpr (!kIsMask) std::memcpy(out.data() + at + 12, rows, 64);
      }
    }
    encoded.crc32 = libdeflate_crc32(0, out.data(), out.size());  // for the file's UUID
  }

  void writeEncodedLayer(uint32_t index, double z, const EncodedMaskLayer& layer) override {
    const std::vector<uint8_t>& encoded = layer.bytes;
    const std::string where = file_.finalPath().string() + ": layer " + std::to_string(index);
    if (index != next_) throw OutputError(where + " arrived, expected " + std::to_string(next_));
    if (encoded.size() % kRecordBytes != 0) throw OutputError(where + " does not match the job's image size");
    if (index == 0) zFirst_ = z;
    content_.add(layer.crc32, encoded.size());
    band_.insert(band_.end(), encoded.begin(), encoded.end());
    bandEnds_[bandLayers_] = band_.size();
    ++bandLayers_;
    ++next_;
    if (bandLayers_ == kBandLayers) endBand();
  }

  void finish(const MaskJob& /*finalJob*/) override {
    if (bandLayers_ > 0) endBand();
    flushGrid();
    try {
      archive_->close(content_.uuid());
    } catch (const std::exception& e) {
      const int err = errno;
      throw OutputError(file_.finalPath().string() +
                        ": cannot write: " + writeFailureReason(file_.tempPath(), err, e.what()));
    }
    archive_.reset();
    file_.commit();
  }

 private:
  // Merges the band's encoded layers (bandFirst .. bandFirst + bandLayers_ - 1, bandFirst a multiple of
  // 8) block by block into the tree: a block lit in all 8 layers becomes a tile, any other lit block a
  // leaf; then closes the slab when the layout has slabs and this one is full.
  void endBand() {
    const uint32_t depth = bandLayers_;
    const uint32_t bandFirst = next_ - depth;
    size_t cursor[kBandLayers], end[kBandLayers];
    for (uint32_t z = 0; z < depth; ++z) {
      cursor[z] = z == 0 ? 0 : bandEnds_[z - 1];
      end[z] = bandEnds_[z];
    }
    mergeBand(depth, bandFirst, cursor, end);
    band_.clear();
    slabLayers_ += depth;
    bandLayers_ = 0;
    if (job_.vdbSlabs && (slabLayers_ >= kVdbSlabLayers || slabLeaves_ * kLeafBytes >= kVdbSlabLeafBytes))
      flushGrid();
  }

  void mergeBand(uint32_t depth, uint32_t bandFirst, size_t* cursor, const size_t* end) {
    openvdb::tree::ValueAccessor<TreeT> access(grid_->tree());
    const ValueT on = toValue_[255];
    const uint8_t* bytes = band_.data();
    auto indexAt = [&](uint32_t z) {
      uint32_t index;
      std::memcpy(&index, bytes + cursor[z], 4);
      return index;
    };
    for (;;) {
      uint32_t block = UINT32_MAX;
      for (uint32_t z = 0; z < depth; ++z)
        if (cursor[z] < end[z]) block = std::min(block, indexAt(z));
      if (block == UINT32_MAX) break;
      // The layers holding this block, and whether every one of the 8 is fully lit.
      const uint8_t* record[kBandLayers] = {};
      bool full = depth == kBandLayers;
      for (uint32_t z = 0; z < depth; ++z) {
        if (cursor[z] < end[z] && indexAt(z) == block) {
          record[z] = bytes + cursor[z];
          cursor[z] += kRecordBytes;
          uint64_t columns;
          std::memcpy(&columns, record[z] + 4, 8);
          full = full && columns == ~uint64_t{0} && (kIsMask || allLit(record[z] + 12));
        } else {
          full = false;
        }
      }
      const openvdb::Coord origin(static_cast<int>(block % blocksX_ * 8),
                                  static_cast<int>(block / blocksX_ * 8), static_cast<int>(bandFirst));
      if (full) {
        access.addTile(1, origin, on, true);  // level 1: a tile the size of one leaf node
        continue;
      }
      LeafT* leaf = access.touchLeaf(origin);
      ++slabLeaves_;
      typename LeafT::NodeMaskType active;  // word x, bit y * 8 + z (LeafNode offset x * 64 + y * 8 + z)
      for (uint32_t z = 0; z < depth; ++z) {
        if (record[z] == nullptr) continue;
        uint64_t columns;
        std::memcpy(&columns, record[z] + 4, 8);
        for (uint32_t x = 0; x < 8; ++x)
          active.template getWord<uint64_t>(x) |= kSpread[(columns >> (8 * x)) & 0xFF] << z;
        if constexpr (!kIsMask) {
          ValueT* values = leaf->buffer().data();
          const uint8_t* pixels = record[z] + 12;
          for (uint32_t y = 0; y < 8; ++y)
            for (uint32_t x = 0; x < 8; ++x)
              if (pixels[y * 8 + x] != 0) values[x * 64 + y * 8 + z] = toValue_[pixels[y * 8 + x]];
        }
      }
      leaf->setValueMask(active);
    }
  }

  static bool allLit(const uint8_t* pixels) {
    for (int i = 0; i < 64; ++i)
      if (pixels[i] != 255) return false;
    return true;
  }

  // Writes the open grid (the whole stack, or one slab) and starts the next one.
  void flushGrid() {
    if (slabLayers_ == 0) return;
    const uint32_t first = next_ - slabLayers_;
    const double p = job_.grid.pixel;
    const openvdb::Vec3d scale(job_.grid.mirrorX ? -p : p, job_.grid.mirrorY ? -p : p, job_.layerHeight);
    const openvdb::Vec3d offset(job_.grid.x0 + (job_.grid.mirrorX ? job_.grid.width - 0.5 : 0.5) * p,
                                job_.grid.y0 + (job_.grid.mirrorY ? job_.grid.height - 0.5 : 0.5) * p,
                                zFirst_);
    openvdb::math::Transform::Ptr transform = openvdb::math::Transform::createLinearTransform(1.0);
    transform->preScale(scale);
    transform->postTranslate(offset);
    grid_->setTransform(transform);
    grid_->setName(job_.vdbSlabs ? slabName(first) : std::string(kVdbGridName));
    if constexpr (!kIsMask) grid_->setGridClass(openvdb::GRID_FOG_VOLUME);
    grid_->insertMeta("first_layer", openvdb::Int32Metadata(static_cast<int32_t>(first)));
    grid_->insertMeta("last_layer", openvdb::Int32Metadata(static_cast<int32_t>(next_ - 1)));
    grid_->insertMeta("layer_height", openvdb::DoubleMetadata(job_.layerHeight));
    grid_->insertMeta("pixel_size", openvdb::DoubleMetadata(p));
    grid_->insertMeta("first_z", openvdb::DoubleMetadata(zFirst_));
    grid_->insertMeta("origin_x", openvdb::DoubleMetadata(job_.grid.x0));
    grid_->insertMeta("origin_y", openvdb::DoubleMetadata(job_.grid.y0));
    grid_->insertMeta("mirror_x", openvdb::BoolMetadata(job_.grid.mirrorX));
    grid_->insertMeta("mirror_y", openvdb::BoolMetadata(job_.grid.mirrorY));
    try {
      archive_->writeSlab(grid_);
    } catch (const std::exception& e) {
      const int err = errno;
      throw OutputError(file_.finalPath().string() +
                        ": cannot write: " + writeFailureReason(file_.tempPath(), err, e.what()));
    }
    grid_ = GridT::create();
    slabLayers_ = 0;
    slabLeaves_ = 0;
  }

  OutputFile file_;  // declared first: destroyed last, after archive_ has closed its stream
  MaskJob job_;
  uint32_t blocksX_, blocksY_;
  std::vector<uint8_t> band_;                   // the band's encoded layers, one after another
  std::array<size_t, kBandLayers> bandEnds_{};  // end of layer z's records in band_
  std::array<ValueT, 256> toValue_{};
  typename GridT::Ptr grid_;  // the open grid
  std::optional<SlabArchive> archive_;
  ContentId content_;
  double zFirst_ = 0;
  uint32_t next_ = 0, bandLayers_ = 0, slabLayers_ = 0;
  size_t slabLeaves_ = 0;
};

int intMeta(const openvdb::GridBase& grid, const char* name) {
  const auto meta = grid.getMetadata<openvdb::Int32Metadata>(name);
  return meta ? meta->value() : -1;
}

std::unique_ptr<MaskSink> makeSink(const std::filesystem::path& path, const MaskJob& job, bool overwrite) {
  if (job.antiAliased) return std::make_unique<VdbSink<openvdb::FloatGrid>>(path, job, overwrite);
  return std::make_unique<VdbSink<openvdb::MaskGrid>>(path, job, overwrite);
}

std::vector<VdbSlab> readSlabs(const std::filesystem::path& file) {
  std::vector<VdbSlab> slabs;
  try {
    openvdb::initialize();
    openvdb::io::File in(file.string());
    in.open(/*delayLoad=*/false);
    for (auto name = in.beginName(); name != in.endName(); ++name) {
      const openvdb::GridBase::Ptr grid = in.readGrid(name.gridName());
      VdbSlab slab;
      slab.name = grid->getName();
      slab.valueType = grid->isType<openvdb::MaskGrid>() ? "mask" : grid->valueType();
      slab.activeVoxels = grid->activeVoxelCount();
      slab.firstLayer = intMeta(*grid, "first_layer");
      slab.lastLayer = intMeta(*grid, "last_layer");
      const openvdb::Vec3d size = grid->transform().voxelSize();
      const openvdb::Vec3d origin = grid->transform().indexToWorld(openvdb::Coord(0, 0, 0));
      slab.voxelSize = {size[0], size[1], size[2]};
      slab.voxelOrigin = {origin[0], origin[1], origin[2]};
      slabs.push_back(std::move(slab));
    }
    in.close();
  } catch (const std::exception& e) {
    throw InputError(file.string() + ": " + e.what());
  }
  return slabs;
}

MaskImage readLayer(const std::filesystem::path& file, uint32_t layer, uint32_t width, uint32_t height) {
  MaskImage image;
  image.width = width;
  image.height = height;
  image.pixels.assign(size_t{width} * height, 0);
  try {
    openvdb::initialize();
    openvdb::io::File in(file.string());
    in.open(/*delayLoad=*/false);
    for (auto name = in.beginName(); name != in.endName(); ++name) {
      const openvdb::GridBase::Ptr meta = in.readGridMetadata(name.gridName());
      const int first = intMeta(*meta, "first_layer"), last = intMeta(*meta, "last_layer");
      if (static_cast<int64_t>(layer) < first || static_cast<int64_t>(layer) > last) continue;
      const openvdb::GridBase::Ptr grid = in.readGrid(name.gridName());
      const int k = static_cast<int>(layer);
      if (const auto mask = openvdb::GridBase::grid<openvdb::MaskGrid>(grid)) {
        const auto access = mask->getConstAccessor();
        for (uint32_t j = 0; j < height; ++j) {
          for (uint32_t i = 0; i < width; ++i) {
            if (access.isValueOn(openvdb::Coord(static_cast<int>(i), static_cast<int>(j), k))) {
              image.pixels[size_t{j} * width + i] = 255;
            }
          }
        }
      } else if (const auto values = openvdb::GridBase::grid<openvdb::FloatGrid>(grid)) {
        const auto access = values->getConstAccessor();
        for (uint32_t j = 0; j < height; ++j) {
          for (uint32_t i = 0; i < width; ++i) {
            const float v = access.getValue(openvdb::Coord(static_cast<int>(i), static_cast<int>(j), k));
            image.pixels[size_t{j} * width + i] =
                static_cast<uint8_t>(std::clamp(std::lround(v * 255.0f), 0l, 255l));
          }
        }
      } else {
        throw InputError(file.string() + ": grid " + name.gridName() + " is neither a mask nor a float grid");
      }
      in.close();
      return image;
    }
  } catch (const InputError&) {
    throw;
  } catch (const std::exception& e) {
    throw InputError(file.string() + ": " + e.what());
  }
  throw InputError(file.string() + ": no grid holds layer " + std::to_string(layer));
}

}  // namespace
}  // namespace toposlice

extern "C" __attribute__((visibility("default"))) const toposlice::VdbModule* toposlice_vdb_module() {
  static const toposlice::VdbModule module{toposlice::kVdbModuleVersion, toposlice::makeSink,
                                           toposlice::readSlabs, toposlice::readLayer};
  return &module;
}
