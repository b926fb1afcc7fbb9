// GDAL helpers shared by the terrain inputs (DEM and imagery): one-time driver registration,
// capture of GDAL's messages, and dataset ownership. Internal to atlas/terrain.
#pragma once

#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <cpl_error.h>
#include <gdal.h>
#include <gdal_priv.h>

namespace gimlod {

inline void registerGdalOnce() {
  static std::once_flag once;
  std::call_once(once, [] { GDALAllRegister(); });
}

// Captures GDAL's messages on this thread (GDAL's handler stack is thread-local) instead of
// letting them go to stderr. Failures are kept for the exception text; warnings for the caller.
class GdalErrorCapture {
 public:
  GdalErrorCapture() {
    CPLErrorReset();
    CPLPushErrorHandlerEx(&handler, this);
  }
  ~GdalErrorCapture() { CPLPopErrorHandler(); }
  GdalErrorCapture(const GdalErrorCapture&) = delete;
  GdalErrorCapture& operator=(const GdalErrorCapture&) = delete;

  // Failure messages since the last clear(), joined with "; ".
  const std::string& failures() const { return failures_; }
  const std::vector<std::string>& warnings() const { return warnings_; }
  void clear() {
    failures_.clear();
    CPLErrorReset();
  }

 private:
  static void CPL_STDCALL handler(CPLErr cls, CPLErrorNum, const char* msg) {
    auto* self = static_cast<GdalErrorCapture*>(CPLGetErrorHandlerUserData());
    if (!self || !msg) return;
    if (cls >= CE_Failure) {
      if (self->failures_.size() < 2000) {
        if (!self->failures_.empty()) self->failures_ += "; ";
        self->failures_ += msg;
      }
    } else if (cls == CE_Warning && self->warnings_.size() < 8) {
      self->warnings_.push_back(std::string("GDAL: ") + msg);
    }
  }
  std::string failures_;
  std::vector<std::string> warnings_;
};

struct DatasetCloser {
  void operator()(GDALDataset* ds) const { GDALClose(GDALDataset::ToHandle(ds)); }
};
using DatasetPtr = std::unique_ptr<GDALDataset, DatasetCloser>;

inline std::string withGdal(const std::string& what, const GdalErrorCapture& cap) {
  return cap.failures().empty() ? what : what + " (" + cap.failures() + ")";
}

}  // namespace gimlod
