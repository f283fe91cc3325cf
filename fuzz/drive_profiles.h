// The shipped drive profiles (config/drives/*.yaml), loaded once, for the fuzz targets that pick
// one by their first input byte (drive_request, modbus_reply). A profile that does not load is
// the harness failing, not the code under test: abort.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "fuzz/fuzz_util.h"
#include "rig/drive_profile.h"

namespace facedyn::fuzz {

inline const std::vector<rig::DriveProfile>& ShippedDriveProfiles() {
  static const std::vector<rig::DriveProfile> profiles = [] {
    std::vector<rig::DriveProfile> out;
    for (const char* name : {"sim", "delta_ms300", "siemens_v20", "invertek_e3"}) {
      auto profile =
          rig::LoadDriveProfile(SourcePath(std::string("config/drives/") + name + ".yaml"));
      if (!profile.ok()) {
        std::fprintf(stderr, "%s\n", profile.status().ToString().c_str());
        std::abort();
      }
      out.push_back(*profile);
    }
    return out;
  }();
  return profiles;
}

}  // namespace facedyn::fuzz
