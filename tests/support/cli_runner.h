#pragma once
// Runs the fluorosim CLI from tests: a per-test temporary folder, captured stdout and stderr, exit
// codes, and a check that an error is one clear line.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "support/temp_dir.h"

namespace fluorosim::testing {

namespace fs = std::filesystem;

inline bool contains(const std::string& haystack, const std::string& needle) { return haystack.find(needle) != std::string::npos; }

inline std::string quote(const std::string& s) {
    std::string q = "'";
    for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return q + "'";
}

inline std::string readFile(const fs::path& p) {
    std::ifstream in(p);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

struct RunResult {
    int exitCode = -1;  // 128+N when killed by signal N (as the shell reports it)
    std::string out, err;
    double seconds = 0;
    // Peak resident memory of the largest child this test process has waited for so far (the kernel
    // keeps only that maximum), in KiB: with one command per test, that command's peak.
    long maxRssKb = 0;
};

// Runs the CLI with `args` behind `launcher` (e.g. mpirun and its options; none by default), stdin from
// /dev/null, stdout and stderr captured to files in `dir`. A generous timeout keeps a misbehaving
// binary from hanging the test run (exit code 124).
inline RunResult runCliUnder(const TempDir& dir, const std::vector<std::string>& launcher, const std::vector<std::string>& args,
                             int timeoutSeconds = 120) {
    const fs::path outFile = dir.path() / "stdout.txt", errFile = dir.path() / "stderr.txt";
    std::string cmd = "timeout -k 5 " + std::to_string(timeoutSeconds);
    for (const auto& l : launcher) cmd += " " + quote(l);
    cmd += " " + quote(FLUOROSIM_CLI);
    for (const auto& a : args) cmd += " " + quote(a);
    cmd += " </dev/null >" + quote(outFile.string()) + " 2>" + quote(errFile.string());
    const auto start = std::chrono::steady_clock::now();
    const int status = std::system(cmd.c_str());
    RunResult r;
    r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    r.exitCode = status == -1 ? -1 : WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    r.out = readFile(outFile);
    r.err = readFile(errFile);
    rusage usage{};
    if (::getrusage(RUSAGE_CHILDREN, &usage) == 0) r.maxRssKb = usage.ru_maxrss;
    return r;
}

inline RunResult runCli(const TempDir& dir, const std::vector<std::string>& args, int timeoutSeconds = 120) {
    return runCliUnder(dir, {}, args, timeoutSeconds);
}

// stderr is exactly one line, starting with "fluorosim: ", containing every part.
inline void expectOneLineError(const RunResult& r, const std::vector<std::string>& parts) {
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << "stderr:\n" << r.err;
    EXPECT_TRUE(!r.err.empty() && r.err.back() == '\n') << "stderr:\n" << r.err;
    EXPECT_EQ(r.err.rfind("fluorosim: ", 0), 0u) << "stderr:\n" << r.err;
    for (const auto& p : parts) EXPECT_TRUE(contains(r.err, p)) << "no \"" << p << "\" in stderr:\n" << r.err;
}

}  // namespace fluorosim::testing
