#pragma once
// A fresh temporary folder per test, removed when the test ends. The name comes from mkdtemp, so tests
// running at the same time (ctest -j2, or another build tree's ctest on the same machine) never share
// a file; the test's name is in it to help whoever finds one left behind.
#include <gtest/gtest.h>
#include <stdlib.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace fluorosim::testing {

class TempDir {
public:
    TempDir() {
        namespace fs = std::filesystem;
        std::string name = "fluorosim_test";
        if (const auto* info = ::testing::UnitTest::GetInstance()->current_test_info())
            name += std::string("_") + info->test_suite_name() + "." + info->name();
        // Parameterised tests have '/' in their names.
        for (char& c : name)
            if (c == '/' || c == ' ') c = '_';
        std::string pattern = (fs::temp_directory_path() / (name + "_XXXXXX")).string();
        std::vector<char> buf(pattern.begin(), pattern.end());
        buf.push_back('\0');
        if (!::mkdtemp(buf.data())) throw std::runtime_error(pattern + ": mkdtemp failed: " + std::strerror(errno));
        path_ = buf.data();
    }
    ~TempDir() {
        std::error_code ec;
        std::filesystem::remove_all(path_, ec);
    }
    TempDir(const TempDir&) = delete;
    TempDir& operator=(const TempDir&) = delete;

    const std::filesystem::path& path() const { return path_; }
    std::filesystem::path file(const std::string& name) const { return path_ / name; }
    // Writes `text` (binary, as given) to `name` in the folder and returns its path.
    std::filesystem::path write(const std::string& name, const std::string& text) const {
        const auto p = path_ / name;
        std::ofstream(p, std::ios::binary) << text;
        return p;
    }

private:
    std::filesystem::path path_;
};

}  // namespace fluorosim::testing
