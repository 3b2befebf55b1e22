// Owns one lib3mf 1.8 object handle (C interface): released when it goes out of scope. Used by the 3MF
// reader and by the tests that write or read 3MF files with lib3mf.
#pragma once

#include "Model/COM/NMR_DLLInterfaces.h"

namespace toposlice {

class Lib3mfHandle {
 public:
  Lib3mfHandle() = default;
  Lib3mfHandle(const Lib3mfHandle&) = delete;
  Lib3mfHandle& operator=(const Lib3mfHandle&) = delete;
  ~Lib3mfHandle() {
    if (p_ != nullptr) NMR::lib3mf_release(p_);
  }
  NMR::PLib3MFBase* get() const { return p_; }
  NMR::PLib3MFBase** out() { return &p_; }

 private:
  NMR::PLib3MFBase* p_ = nullptr;
};

}  // namespace toposlice
