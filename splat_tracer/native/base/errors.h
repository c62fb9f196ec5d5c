// The exceptions the core throws across its own files. The bindings (python/py_util.h,
// run_native) turn them into Python exceptions.
#pragma once

#include <stdexcept>

namespace splat {

// Raised for input the core cannot work with (a non-finite coordinate, a zero normal, an
// index out of range...), naming the first offending element; the bindings turn it into
// ValueError.
struct InputError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

}  // namespace splat
