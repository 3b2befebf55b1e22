// Printer and material profiles (issue "Production print settings"; docs/FORMATS.md, "Profile files").
//
// Every setting is a key named as PrusaSlicer 2.5 names it (`prusa-slicer --help-sla`), with its meaning;
// toposlice's own additions are marked in settingKeys(). Values are resolved in this order, each step
// overriding the one before:
//   1. the defaults (PrintSettings as constructed);
//   2. the printer: a built-in preset (sl1, sl1s, generic-4k) or a `printers` entry of the profile
//      file, after what it `inherits`;
//   3. the material: a built-in preset (default) or a `materials` entry of the profile file;
//   4. overrides (command-line options, `--set KEY=VALUE`, a batch job's `print_settings`), in order.
// Every value is checked where it is read: a key of the wrong kind (a material key in a printer), an
// unknown key (with the nearest known one), a value out of range or not a number is an InputError that
// names the file, the profile and the key.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace toposlice {

struct PrintSettings {
  // Printer.
  std::string printerName;                            // the chosen preset or profile; empty: none
  std::string printerModel = "SL1";                   // printer_model (SL1 printerModel)
  uint32_t pixelsX = 0, pixelsY = 0;                  // display_pixels_x / _y
  double displayWidth = 0, displayHeight = 0;         // display_width / _height, mm; 0: unknown
  bool mirrorX = false, mirrorY = false;              // display_mirror_x / _y
  std::string orientation = "landscape";              // display_orientation
  double maxPrintHeight = 0;                          // max_print_height, mm; 0: no limit
  std::array<double, 3> relativeCorrection{1, 1, 1};  // relative_correction_x / _y / _z
  double absoluteCorrection = 0;                      // absolute_correction, mm
  double elefantFootCompensation = 0;                 // elefant_foot_compensation, mm
  double elefantFootMinWidth = 0.2;                   // elefant_foot_min_width, mm
  uint32_t elefantFootLayers = 0;                     // elefant_foot_layers (toposlice); 0: faded_layers
  std::optional<double> gammaCorrection;              // gamma_correction; unset: --antialias decides
  std::filesystem::path lightMap;                     // light_map (toposlice): grayscale PNG; empty: none
  // Platform motion and light (toposlice keys; written where printer files carry them: GOO, NanoDLP).
  double liftDistance = 5.0, liftSpeed = 65.0;              // lift_distance mm, lift_speed mm/min
  double bottomLiftDistance = 5.0, bottomLiftSpeed = 65.0;  // bottom_lift_distance, bottom_lift_speed
  double retractSpeed = 150.0;                              // retract_speed, mm/min
  double waitBeforeExposure = 1.0;                          // wait_before_exposure, s (resin settling)
  uint32_t lightPwm = 255;                                  // light_pwm, UV power 0..255
  // Material.
  std::string materialName = "default";               // the chosen material preset or profile
  double exposureTime = 8.0;                          // exposure_time, s
  double initialExposureTime = 35.0;                  // initial_exposure_time, s
  uint32_t fadedLayers = 10;                          // faded_layers
  std::array<double, 3> materialCorrection{1, 1, 1};  // material_correction_x / _y / _z
  double materialDensity = 1.0;                       // material_density, g/ml
  // Layers over which the elephant-foot shrink fades: elefant_foot_layers when set, else faded_layers
  // (PrusaSlicer applies it over the material's faded layers).
  uint32_t elephantFootFadeLayers() const { return elefantFootLayers > 0 ? elefantFootLayers : fadedLayers; }
  // Where each key's value came from when not the default ("printer sl1", "profile lab.json printer
  // lab-sl1", "command line"), by key.
  std::map<std::string, std::string> origin;

  // The scaling correction: relative_correction times material_correction, per axis.
  std::array<double, 3> scale() const {
    return {relativeCorrection[0] * materialCorrection[0], relativeCorrection[1] * materialCorrection[1],
            relativeCorrection[2] * materialCorrection[2]};
  }
  bool scales() const {
    const auto s = scale();
    return s[0] != 1 || s[1] != 1 || s[2] != 1;
  }
  // An outline correction (absolute_correction, an elephant foot) moves the contours off the mesh's cuts.
  bool correctsOutlines() const { return absoluteCorrection != 0 || elefantFootCompensation > 0; }
  bool set(std::string_view key) const { return origin.count(std::string(key)) > 0; }
};

enum class SettingOwner { Printer, Material };

struct SettingKey {
  const char* name;    // PrusaSlicer's key; the command-line option is "--" + name with '_' -> '-'
  SettingOwner owner;  // printer or material
  const char* help;    // one line, with the unit
  bool toposliceOnly;  // not a PrusaSlicer key
};

// Every key, in documentation order.
std::span<const SettingKey> settingKeys();

// Why `key`, a setting the user gave explicitly, would do nothing in a job whose mask outputs are
// `maskOutputs` (none: a contour-only job), or "" when it applies. Settings that only the masks use
// need a mask output ("it needs " + `maskOutputName`, what the job would have to give); the ones that are
// only written into the printer file (printer_model, the exposures, the motion and light keys) need a mask
// format that carries them: SL1 the model and exposures, NanoDLP the exposures and the lift, retract and wait
// keys, GOO all of them, EXR and VDB all (as metadata), a PNG folder none. material_density only gives
// the resin mass: it needs a `summary` (slice's --summary) or masks that record it (.sl1, .sl1s, .goo,
// .exr, .vdb).
std::string settingUnusedReason(std::string_view key, std::span<const std::filesystem::path> maskOutputs,
                                std::string_view maskOutputName, bool summary = false);

// Which profiles to use and the overrides (key, value text) on top.
struct ProfileChoice {
  std::filesystem::path file;  // profile file (JSON); empty: built-in presets only
  std::string printer;         // preset or profile name; empty: the file's only printer, or none
  std::string material;        // preset or profile name; empty: the file's only material, or "default"
  std::vector<std::pair<std::string, std::string>> overrides;
  std::string overrideOrigin = "command line";
  // Where the printer and material names were given ("--printer", "job.json: settings.printer"): an
  // unknown name is reported there. Empty: the message names no place.
  std::string printerWhere, materialWhere;
};

// Resolves the settings (order above). Throws InputError for an unknown printer or material (naming the
// known ones), an unreadable or malformed file, or a bad key or value.
PrintSettings resolvePrintSettings(const ProfileChoice& choice);

// Sets one key from its text ("0.05", "1", "true", "portrait", a path), recording `origin`. Throws
// InputError("<origin>: <key>: <what>") for an unknown key or a bad value.
void assignSetting(PrintSettings& settings, std::string_view key, std::string_view value,
                   const std::string& origin);

// A job's "mirror" setting (batch and plate jobs: none, x, y or xy, both set or neither) is the display's
// mirroring: it replaces the printer's display_mirror_x/_y ("none" turns a printer's mirror off), with
// `origin` as where they came from.
void applyJobMirror(PrintSettings& settings, std::optional<bool> mirrorX, std::optional<bool> mirrorY,
                    const std::string& origin);

// Every key with its value as text, in settingKeys() order (for the SL1 ini files, the summary and
// metadata): numbers in the shortest form that reads back exactly, flags as 0/1.
std::vector<std::pair<std::string, std::string>> settingValues(const PrintSettings& settings);

// Names of the built-in presets, for help texts: printers ("sl1, sl1s, generic-4k") and materials.
std::string builtInMaterialNames();

}  // namespace toposlice
