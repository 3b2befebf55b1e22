// SL1 archive writer. Keys follow what the readers actually parse: PrusaSlicer's SL1 import
// (get_raster_params needs display_pixels_x/y, display_width/height, display_mirror_x/y and
// display_orientation in prusaslicer.ini; layer_height falls back to config.ini's layerHeight), UVtools'
// SL1File (config.ini and prusaslicer.ini must both exist; layer count = numSlow + numFast; resolution
// from display_pixels_x/y) and the SL1 firmware's project config (jobDir is the PNG name prefix,
// numFade >= 2 because the fade divides by numFade - 1, printerModel must match the printer,
// layerHeightFirst defaults to 0.05 mm when absent).
#include "io/masks/sl1_writer.h"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <map>
#include <optional>
#include <span>
#include <system_error>
#include <vector>

#include <fcntl.h>
#include <minizip/zip.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include "io/errors.h"
#include "io/masks/mask_png.h"
#include "io/output_file.h"

namespace toposlice {
namespace {

using IniMap = std::map<std::string, std::string>;

std::string number(double v) {
  char buf[512];  // the longest fixed double (a denormal) has about 330 characters
  const auto result = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::fixed);  // never "1e+05"
  return std::string(buf, result.ptr);
}

std::string number(uint64_t v) {
  return std::to_string(v);
}

std::string toIni(const IniMap& m) {
  std::string text;
  for (const auto& [key, value] : m) text += key + " = " + value + "\n";
  return text;
}

std::string modelOf(const MaskJob& job) {
  return job.printerModel.empty() ? "SL1" : job.printerModel;
}

uint32_t fadeLayersOf(const MaskJob& job) {
  return std::clamp<uint32_t>(job.fadeLayers, 2, 200);
}

// Exposure of layer i, as the firmware computes it: the first layer gets initialExposureTime, the
// following fade - 2 layers step linearly towards exposureTime, the rest get exposureTime.
double estimatedPrintTime(const MaskJob& job, uint32_t layers) {
  const uint32_t fade = fadeLayersOf(job);
  const double step = (job.initialExposureTime - job.exposureTime) / (fade - 1);
  double total = 0;
  for (uint32_t i = 0; i < layers && i + 1 < fade; ++i) total += job.initialExposureTime - i * step;
  if (layers + 1 > fade) total += (layers - (fade - 1)) * job.exposureTime;
  return total + layers * kSl1LayerOverheadS;
}

std::time_t creationTime(const MaskJob& job) {
  constexpr std::time_t kZipEpoch = 315532800;  // 1980-01-01 00:00:00 UTC, the earliest zip time
  return std::max(maskCreationTime(job), kZipEpoch);
}

uint32_t getLE32(const uint8_t* p) {
  return uint32_t{p[0]} | uint32_t{p[1]} << 8 | uint32_t{p[2]} << 16 | uint32_t{p[3]} << 24;
}

void putLE(uint8_t* p, uint64_t v, int bytes) {
  for (int i = 0; i < bytes; ++i) p[i] = static_cast<uint8_t>(v >> (8 * i));
}

// minizip 1.1 as shipped by Debian 12 writes the Zip64 end records only past 4 GiB; with 65,535 entries
// or more it writes 0xFFFF counts into the classic end record and no Zip64 record, which strict readers
// (libzip, unzip, .NET's ZipArchive used by UVtools) reject. This replaces the classic end record by a
// Zip64 end record, its locator and a classic record pointing to them (APPNOTE 4.3.14-4.3.16). A
// no-op when minizip already wrote them or the count fits.
void addZip64EndRecords(const std::filesystem::path& file, uint64_t entries) {
  if (entries < 0xFFFF) return;
  const auto fail = [&file](const char* what) {
    throw OutputError(file.string() + ": " + what + ": " + std::generic_category().message(errno));
  };
  const int fd = ::open(file.c_str(), O_RDWR | O_CLOEXEC);
  if (fd < 0) fail("cannot reopen");
  struct stat st {};
  uint8_t end[22 + 20];  // possible Zip64 locator, then the classic end record (no comment)
  if (::fstat(fd, &st) != 0 || st.st_size < static_cast<off_t>(sizeof end) ||
      ::pread(fd, end, sizeof end, st.st_size - static_cast<off_t>(sizeof end)) !=
          static_cast<ssize_t>(sizeof end)) {
    ::close(fd);
    fail("cannot read the end record");
  }
  const uint8_t* eocd = end + 20;
  if (getLE32(eocd) != 0x06054b50u || getLE32(end) == 0x07064b50u) {
    ::close(fd);
    if (getLE32(eocd) != 0x06054b50u) throw OutputError(file.string() + ": unexpected zip end record");
    return;  // Zip64 records present
  }
  const uint64_t cdSize = getLE32(eocd + 12), cdOffset = getLE32(eocd + 16);
  const uint64_t zip64At = static_cast<uint64_t>(st.st_size) - 22;
  uint8_t tail[56 + 20 + 22] = {};
  uint8_t* z = tail;  // Zip64 end of central directory record
  putLE(z, 0x06064b50u, 4);
  putLE(z + 4, 56 - 12, 8);   // size of the rest of the record
  putLE(z + 12, 45, 2);       // version made by: 4.5 (Zip64)
  putLE(z + 14, 45, 2);       // version needed
  putLE(z + 24, entries, 8);  // entries on this disk (disk numbers stay 0)
  putLE(z + 32, entries, 8);  // entries in total
  putLE(z + 40, cdSize, 8);
  putLE(z + 48, cdOffset, 8);
  uint8_t* l = tail + 56;  // Zip64 end of central directory locator
  putLE(l, 0x07064b50u, 4);
  putLE(l + 8, zip64At, 8);
  putLE(l + 16, 1, 4);     // total number of disks
  uint8_t* e = tail + 76;  // classic end record, counts deferring to the Zip64 record
  putLE(e, 0x06054b50u, 4);
  putLE(e + 8, 0xFFFF, 2);
  putLE(e + 10, 0xFFFF, 2);
  putLE(e + 12, cdSize, 4);
  putLE(e + 16, cdOffset, 4);
  if (::pwrite(fd, tail, sizeof tail, static_cast<off_t>(zip64At)) != static_cast<ssize_t>(sizeof tail)) {
    ::close(fd);
    fail("cannot write the Zip64 end record");
  }
  if (::close(fd) != 0) fail("cannot write the Zip64 end record");
}

std::string errorText(int code) {
  return code == ZIP_ERRNO ? std::generic_category().message(errno) : "zip error " + std::to_string(code);
}

class Sl1Sink final : public EncodingMaskSink {
 public:
  Sl1Sink(const std::filesystem::path& path, const MaskJob& job, bool overwrite)
      : file_(path, overwrite), job_(job), created_(creationTime(job)) {
    if (job.layerCount > kSl1MaxLayers) {
      throw OutputError(path.string() + ": an SL1 archive holds at most " + std::to_string(kSl1MaxLayers) +
                        " layers (5-digit layer names); this job has " + std::to_string(job.layerCount));
    }
    // minizip writes the temporary through its own handle; file_ owns its name, its removal when
    // abandoned (signals included) and the final rename. file_ itself never writes a byte.
    zip_ = zipOpen64(file_.tempPath().c_str(), APPEND_STATUS_CREATE);
    if (zip_ == nullptr) {
      throw OutputError(path.string() + ": cannot create " + file_.tempPath().string() + ": " +
                        std::generic_category().message(errno));
    }
    std::tm t{};
    gmtime_r(&created_, &t);
    info_.tmz_date.tm_sec = static_cast<uInt>(t.tm_sec);
    info_.tmz_date.tm_min = static_cast<uInt>(t.tm_min);
    info_.tmz_date.tm_hour = static_cast<uInt>(t.tm_hour);
    info_.tmz_date.tm_mday = static_cast<uInt>(t.tm_mday);
    info_.tmz_date.tm_mon = static_cast<uInt>(t.tm_mon);
    info_.tmz_date.tm_year = static_cast<uInt>(t.tm_year + 1900);
  }

  ~Sl1Sink() override {
    if (zip_ != nullptr) zipClose(zip_, nullptr);  // then file_ removes the temporary
  }

  // The layer's PNG and its CRC-32: the zip entry is then written raw, without a second pass over it.
  void encodeLayer(uint32_t index, double /*z*/, const MaskImage& mask, EncodedMaskLayer& out,
                   MaskEncodeScratch& scratch) const override {
    checkMaskLayerSize(mask, job_.grid, file_.finalPath(), index);
    encodeMaskPng(mask, out.bytes, scratch.deflate);
    out.crc32 = static_cast<uint32_t>(crc32_z(0, out.bytes.data(), out.bytes.size()));
  }

  void writeEncodedLayer(uint32_t index, double /*z*/, const EncodedMaskLayer& layer) override {
    if (index != next_ || index >= kSl1MaxLayers) {
      throw OutputError(file_.finalPath().string() + ": layer " + std::to_string(index) +
                        " arrived, expected " + std::to_string(next_));
    }
    addEntry(maskLayerFileName(job_.name, index, kSl1MaxLayers, "png"), layer.bytes, layer.crc32);
    ++next_;
  }

  void finish(const MaskJob& finalJob) override {
    MaskJob job = finalJob;
    job.name = job_.name;  // the PNG names already written fix jobDir
    const std::string config = sl1ConfigIni(job, next_, created_);
    const std::string profile = sl1PrusaSlicerIni(job, next_);
    addEntry("config.ini", {reinterpret_cast<const uint8_t*>(config.data()), config.size()});
    addEntry("prusaslicer.ini", {reinterpret_cast<const uint8_t*>(profile.data()), profile.size()});
    const int rc = zipClose(zip_, nullptr);
    zip_ = nullptr;
    if (rc != ZIP_OK) throw OutputError(file_.finalPath().string() + ": cannot write: " + errorText(rc));
    addZip64EndRecords(file_.tempPath(), uint64_t{next_} + 2);
    file_.commit();
  }

 private:
  // With a known CRC-32 the entry is written raw (minizip does not checksum the bytes again).
  void addEntry(const std::string& name, std::span<const uint8_t> data,
                std::optional<uint32_t> crc = std::nullopt) {
    // Stored (method 0), names flagged UTF-8 (general purpose bit 11). Entries are far below 4 GiB, so
    // no per-entry Zip64 fields; minizip adds them for offsets past 4 GiB.
    constexpr uLong kUtf8Names = 1u << 11;
    const int raw = crc ? 1 : 0;
    int rc =
        zipOpenNewFileInZip4_64(zip_, name.c_str(), &info_, nullptr, 0, nullptr, 0, nullptr, 0, 0, raw,
                                -MAX_WBITS, DEF_MEM_LEVEL, Z_DEFAULT_STRATEGY, nullptr, 0, 0, kUtf8Names, 0);
    if (rc == ZIP_OK) rc = zipWriteInFileInZip(zip_, data.data(), static_cast<unsigned>(data.size()));
    if (rc == ZIP_OK) rc = crc ? zipCloseFileInZipRaw64(zip_, data.size(), *crc) : zipCloseFileInZip(zip_);
    if (rc != ZIP_OK) {
      throw OutputError(file_.finalPath().string() + ": cannot write " + name + ": " + errorText(rc));
    }
  }

  OutputFile file_;  // declared first: destroyed last, after the destructor has closed zip_
  MaskJob job_;
  std::time_t created_;
  zipFile zip_ = nullptr;
  zip_fileinfo info_{};
  uint32_t next_ = 0;
};

}  // namespace

std::unique_ptr<MaskSink> makeSl1Sink(const std::filesystem::path& path, const MaskJob& job, bool overwrite) {
  return std::make_unique<Sl1Sink>(path, job, overwrite);
}

std::string sl1ConfigIni(const MaskJob& job, uint32_t layers, std::time_t created) {
  std::tm t{};
  gmtime_r(&created, &t);
  char stamp[64];
  std::strftime(stamp, sizeof stamp, "%Y-%m-%d at %H:%M:%S UTC", &t);
  IniMap m;
  m["action"] = "print";
  m["jobDir"] = maskFilePrefix(job.name);
  m["expTime"] = number(job.exposureTime);
  m["expTimeFirst"] = number(job.initialExposureTime);
  m["expUserProfile"] = "0";
  m["fileCreationTimestamp"] = stamp;
  m["hollow"] = "0";
  m["layerHeight"] = number(job.layerHeight);
  m["layerHeightFirst"] = number(job.layerHeight);
  m["materialName"] = "toposlice";
  m["numFade"] = number(uint64_t{fadeLayersOf(job)});
  m["numFast"] = number(uint64_t{layers});
  m["numSlow"] = "0";
  m["printProfile"] = "toposlice";
  m["printTime"] = number(std::round(estimatedPrintTime(job, layers)));
  m["printerModel"] = modelOf(job);
  m["printerProfile"] = "toposlice";
  m["printerVariant"] = "default";
  m["prusaSlicerVersion"] = "toposlice";
  m["usedMaterial"] = number(std::round(job.volumeMl * 1000) / 1000);
  return toIni(m);
}

std::string sl1PrusaSlicerIni(const MaskJob& job, uint32_t layers) {
  const double width = job.grid.width * job.grid.pixel, height = job.grid.height * job.grid.pixel;
  const double printHeight = std::max(150.0, std::ceil(layers * job.layerHeight));
  IniMap m;
  m["absolute_correction"] = "0";
  m["area_fill"] = "50";
  m["bed_shape"] =
      "0x0," + number(width) + "x0," + number(width) + "x" + number(height) + ",0x" + number(height);
  m["display_height"] = number(height);
  m["display_mirror_x"] = job.grid.mirrorX ? "1" : "0";
  m["display_mirror_y"] = job.grid.mirrorY ? "1" : "0";
  m["display_orientation"] = "landscape";
  m["display_pixels_x"] = number(uint64_t{job.grid.width});
  m["display_pixels_y"] = number(uint64_t{job.grid.height});
  m["display_width"] = number(width);
  m["elefant_foot_compensation"] = "0";
  m["exposure_time"] = number(job.exposureTime);
  m["faded_layers"] = number(uint64_t{fadeLayersOf(job)});
  m["gamma_correction"] = job.antiAliased ? "1" : "0";
  m["hollowing_enable"] = "0";
  m["initial_exposure_time"] = number(job.initialExposureTime);
  m["initial_layer_height"] = number(job.layerHeight);
  m["layer_height"] = number(job.layerHeight);
  m["material_print_speed"] = "fast";
  m["max_print_height"] = number(printHeight);
  m["pad_enable"] = "0";
  m["printer_model"] = modelOf(job);
  m["printer_settings_id"] = "toposlice";
  m["printer_technology"] = "SLA";
  m["printer_variant"] = "default";
  m["sla_material_settings_id"] = "toposlice";
  m["sla_print_settings_id"] = "toposlice";
  m["supports_enable"] = "0";
  return toIni(m);
}

}  // namespace toposlice
