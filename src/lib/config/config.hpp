// Internals of the configuration-file library (chimera/config.h), shared
// by document.cpp (parsing, paths, keys) and values.cpp (typed getters).
#pragma once

#include "toml.hpp"

#include <cerrno>
#include <cstdarg>
#include <new>
#include <string>

#include "chimera/config.h"

struct chm_config {
    std::string name;  // what messages call the document
    toml::table root;
};

namespace chm::config {

// Sets this thread's chm_config_last_error() text; returns `status`.
// Never throws (it runs in the exception handlers of guarded()).
int fail(int status, const char* msg) noexcept;
int fail(int status, const std::string& msg) noexcept;
int failf(int status, const char* fmt, ...) noexcept __attribute__((format(printf, 2, 3)));

// "name:line:column" of a node (the root table, which has no place of its
// own, is line 1, column 1).
std::string where(const chm_config* cfg, const toml::node* n);

// A value as messages show it: `integer 5`, `string "abc"`, `table`...
std::string describe(const toml::node* n);

// A number printed so that it reads back the same.
std::string num(double v);

// The result of following a key path.
struct Found {
    const toml::node* node = nullptr;    // the value, or nullptr when absent
    const toml::node* holder = nullptr;  // when absent: the deepest container found
    std::string holder_path;             // and its path ("" for the root)
    std::string missing;                 // and the step it lacks ("'gain'", "[3]")
};

// Follows `key` from the root. Errors (message set): -EINVAL NULL or
// malformed path; -EBADMSG a step goes through a non-container.
int lookup(const chm_config* cfg, const char* key, Found* f);

// For an absent required value: "name:l:c: key: expected X, got nothing
// (...)" and -ENOENT.
int absent(const chm_config* cfg, const char* key, const Found& f, const std::string& expected);

// For a present value of the wrong type or range: -EBADMSG.
int wrong(const chm_config* cfg, const char* key, const toml::node* n,
          const std::string& expected, const std::string& why = "");

// Runs `body`, turning any exception into a status: nothing crosses the C API.
template <typename F>
int guarded(F&& body) noexcept {
    try {
        return body();
    } catch (const std::bad_alloc&) {
        return fail(-ENOMEM, "out of memory");
    } catch (...) {
        return fail(-EIO, "internal error in the configuration library");
    }
}

}  // namespace chm::config
