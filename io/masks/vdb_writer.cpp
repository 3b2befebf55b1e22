// OpenVDB mask stack writer (OpenVDB 10: io::Archive, Tree::touchLeaf/addTile, math::Transform).
// Built into the OpenVDB module (io/masks/vdb_module.h), not into toposlice_io.
#include "io/masks/vdb_writer.h"
#include "io/masks/vdb_module.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <exception>
#include <fstream>
#include <optional>
#include <type_traits>

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

// A .vdb file written one grid at a time: the layout of io::File::write (header, file metadata, grid
// count, then each grid with its descriptor and offsets), built from io::Archive's protected pieces. The
// grid count is written as 0 and patched by close().
class SlabArchive : public openvdb::io::Archive {
 public:
  SlabArchive(const std::filesystem::path& path, const openvdb::MetaMap& fileMeta) {
    os_.open(path, std::ios_base::out | std::ios_base::binary | std::ios_base::trunc);
    if (!os_) throw openvdb::IoError("could not open " + path.string() + " for writing");
    streamMeta_ = std::make_shared<openvdb::io::StreamMetadata>();
    openvdb::io::setStreamMetadataPtr(os_, streamMeta_, /*transfer=*/false);
    openvdb::io::setDataCompression(os_, compression());
    openvdb::io::setWriteGridStatsMetadata(os_, isGridStatsMetadataEnabled());
    writeHeader(os_, /*seekable=*/true);
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

  void close() {
    const std::streampos end = os_.tellp();
    os_.seekp(countPos_);
    os_.write(reinterpret_cast<const char*>(&count_), sizeof count_);
    os_.seekp(end);
    os_.close();
    if (!os_) throw openvdb::IoError("write failed");
  }

 private:
  std::ofstream os_;
  openvdb::io::StreamMetadata::Ptr streamMeta_;  // must outlive every write to os_
  std::streampos countPos_{};
  int32_t count_ = 0;
};

bool hasZeroByte(uint64_t x) {
  return ((x - 0x0101010101010101ull) & ~x & 0x8080808080808080ull) != 0;
}

std::string slabName(uint32_t firstLayer) {
  std::string digits = std::to_string(firstLayer);
  if (digits.size() < 5) digits.insert(0, 5 - digits.size(), '0');
  return "mask_" + digits;
}

template <class GridT>
class VdbSink final : public MaskSink {
  using TreeT = typename GridT::TreeType;
  using LeafT = typename TreeT::LeafNodeType;
  using ValueT = typename GridT::ValueType;
  static constexpr bool kIsMask = std::is_same_v<ValueT, bool>;
  static constexpr std::size_t kLeafBytes = sizeof(LeafT) + (kIsMask ? 0 : LeafT::SIZE * sizeof(ValueT));

 public:
  VdbSink(const std::filesystem::path& path, const MaskJob& job, bool overwrite)
      : file_(path, overwrite), job_(job), plane_(size_t{job.grid.width} * job.grid.height) {
    openvdb::initialize();
    band_.resize(plane_ * kBandLayers);
    for (int v = 0; v < 256; ++v) {
      if constexpr (kIsMask) {
        toValue_[v] = v != 0;
      } else {
        toValue_[v] = static_cast<float>(v) / 255.0f;
      }
    }
    grid_ = GridT::create();
    openvdb::MetaMap fileMeta;
    fileMeta.insertMeta("creator", openvdb::StringMetadata("toposlice"));
    fileMeta.insertMeta("layer_count", openvdb::Int32Metadata(static_cast<int32_t>(job.layerCount)));
    fileMeta.insertMeta("layer_height", openvdb::DoubleMetadata(job.layerHeight));
    fileMeta.insertMeta("pixel_size", openvdb::DoubleMetadata(job.grid.pixel));
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

  void writeLayer(uint32_t index, double z, const MaskImage& mask) override {
    const std::string where = file_.finalPath().string() + ": layer " + std::to_string(index);
    if (index != next_) throw OutputError(where + " arrived, expected " + std::to_string(next_));
    if (mask.width != job_.grid.width || mask.height != job_.grid.height || mask.pixels.size() != plane_) {
      throw OutputError(where + " does not match the job's image size");
    }
    if (index == 0) zFirst_ = z;
    std::memcpy(band_.data() + plane_ * (index % kBandLayers), mask.pixels.data(), plane_);
    ++bandLayers_;
    ++next_;
    if (bandLayers_ == kBandLayers) endBand();
  }

  void finish(const MaskJob& /*finalJob*/) override {
    if (bandLayers_ > 0) endBand();
    flushSlab();
    try {
      archive_->close();
    } catch (const std::exception& e) {
      const int err = errno;
      throw OutputError(file_.finalPath().string() +
                        ": cannot write: " + writeFailureReason(file_.tempPath(), err, e.what()));
    }
    archive_.reset();
    file_.commit();
  }

 private:
  // Turns the buffered band (layers bandFirst .. bandFirst + bandLayers_ - 1, bandFirst a multiple of
  // 8) into tiles and leaves of the slab's tree, then closes the slab when it is full.
  void endBand() {
    const uint32_t width = job_.grid.width, height = job_.grid.height, depth = bandLayers_;
    const uint32_t bandFirst = next_ - depth;
    TreeT& tree = grid_->tree();
    const ValueT on = toValue_[255];
    for (uint32_t by = 0; by < height; by += 8) {
      const uint32_t ny = std::min(8u, height - by);
      for (uint32_t bx = 0; bx < width; bx += 8) {
        const uint32_t nx = std::min(8u, width - bx);
        bool any = false;
        bool full = nx == 8 && ny == 8 && depth == kBandLayers;
        for (uint32_t kz = 0; kz < depth; ++kz) {
          for (uint32_t y = 0; y < ny; ++y) {
            const uint8_t* row = band_.data() + plane_ * kz + size_t{by + y} * width + bx;
            if (nx == 8) {
              uint64_t word;
              std::memcpy(&word, row, 8);
              any = any || word != 0;
              full = full && (kIsMask ? !hasZeroByte(word) : word == ~uint64_t{0});
            } else {
              for (uint32_t x = 0; x < nx; ++x) any = any || row[x] != 0;
            }
          }
        }
        if (!any) continue;
        const openvdb::Coord origin(static_cast<int>(bx), static_cast<int>(by), static_cast<int>(bandFirst));
        if (full) {
          tree.addTile(1, origin, on, true);  // level 1: a tile the size of one leaf node
          continue;
        }
        LeafT* leaf = tree.touchLeaf(origin);
        ++slabLeaves_;
        for (uint32_t kz = 0; kz < depth; ++kz) {
          for (uint32_t y = 0; y < ny; ++y) {
            const uint8_t* row = band_.data() + plane_ * kz + size_t{by + y} * width + bx;
            for (uint32_t x = 0; x < nx; ++x) {
              if (row[x] == 0) continue;
              const openvdb::Index offset = LeafT::coordToOffset(
                  origin.offsetBy(static_cast<int>(x), static_cast<int>(y), static_cast<int>(kz)));
              if constexpr (kIsMask) {
                leaf->setValueOn(offset);
              } else {
                leaf->setValueOn(offset, toValue_[row[x]]);
              }
            }
          }
        }
      }
    }
    slabLayers_ += depth;
    bandLayers_ = 0;
    if (slabLayers_ >= kVdbSlabLayers || slabLeaves_ * kLeafBytes >= kVdbSlabLeafBytes) flushSlab();
  }

  void flushSlab() {
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
    grid_->setName(slabName(first));
    if constexpr (!kIsMask) grid_->setGridClass(openvdb::GRID_FOG_VOLUME);
    grid_->insertMeta("first_layer", openvdb::Int32Metadata(static_cast<int32_t>(first)));
    grid_->insertMeta("last_layer", openvdb::Int32Metadata(static_cast<int32_t>(next_ - 1)));
    grid_->insertMeta("layer_height", openvdb::DoubleMetadata(job_.layerHeight));
    grid_->insertMeta("pixel_size", openvdb::DoubleMetadata(p));
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
  size_t plane_;
  std::vector<uint8_t> band_;  // kBandLayers layers, each plane_ bytes, rows bottom-up
  std::array<ValueT, 256> toValue_{};
  typename GridT::Ptr grid_;  // the open slab
  std::optional<SlabArchive> archive_;
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
