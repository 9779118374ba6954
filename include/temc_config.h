/* temc: neural denoiser for spectral Monte Carlo renders. The counterpart of Intel Open
 * Image Denoise's public OpenImageDenoise/config.h under the temc names: version,
 * namespace, import/export and feature macros. temc.h includes it as oidn.h includes
 * config.h. The version lines are written from Cargo.toml: tests/c_header.rs fails when
 * they drift, and `TEMC_BLESS=1 cargo test --release --test c_header` rewrites them. */

#ifndef TEMC_CONFIG_H
#define TEMC_CONFIG_H

/* The OIDN API level the C ABI implements (Cargo.toml, [package.metadata.temc]
 * oidn-api-version), so that a client's OIDN 2.x checks take their 2.x path; also the
 * device parameters "version", "versionMajor", "versionMinor" and "versionPatch". */
#define TEMC_VERSION_MAJOR 2
#define TEMC_VERSION_MINOR 3
#define TEMC_VERSION_PATCH 0
#define TEMC_VERSION 20300
#define TEMC_VERSION_STRING "2.3.0"
#define TEMC_VERSION_STRING_SHORT "2.3.0"

/* temc's own version (Cargo.toml's package version; the device parameter
 * "libraryVersion"), for clients that use what only temc has, such as "spectral". */
#define TEMC_LIBRARY_VERSION_MAJOR 0
#define TEMC_LIBRARY_VERSION_MINOR 1
#define TEMC_LIBRARY_VERSION_PATCH 0
#define TEMC_LIBRARY_VERSION 100
#define TEMC_LIBRARY_VERSION_STRING "0.1.0"

/* No API namespace: the functions are plain C symbols exported by rustc, so
 * TEMC_API_NAMESPACE stays undefined (as in OIDN's default build) and its
 * BEGIN/END/USING expand to nothing. The C++ wrapper temc.hpp lives in TEMC_NAMESPACE. */
#define TEMC_API_NAMESPACE_BEGIN
#define TEMC_API_NAMESPACE_END
#define TEMC_API_NAMESPACE_USING
#define TEMC_NAMESPACE temc
#define TEMC_NAMESPACE_C temc
#define TEMC_NAMESPACE_BEGIN namespace temc {
#define TEMC_NAMESPACE_END }
#define TEMC_NAMESPACE_USING using namespace TEMC_NAMESPACE;

#if defined(__cplusplus)
#define TEMC_API_EXTERN_C extern "C"
#else
#define TEMC_API_EXTERN_C
#endif

/* What temc.h puts before each function. Define TEMC_STATIC_LIB before including it when
 * linking libtemc.a on Windows, where a DLL import would not resolve. */
#if defined(TEMC_STATIC_LIB)
#define TEMC_API_IMPORT TEMC_API_EXTERN_C
#define TEMC_API_EXPORT TEMC_API_EXTERN_C
#elif defined(_WIN32)
#define TEMC_API_IMPORT TEMC_API_EXTERN_C __declspec(dllimport)
#define TEMC_API_EXPORT TEMC_API_EXTERN_C __declspec(dllexport)
#else
#define TEMC_API_IMPORT TEMC_API_EXTERN_C
#define TEMC_API_EXPORT TEMC_API_EXTERN_C __attribute__((visibility("default")))
#endif

/* rustc builds the library, never a C compiler from these headers: C code only imports. */
#define TEMC_API TEMC_API_IMPORT

#if defined(__cplusplus) && __cplusplus >= 201402L
#define TEMC_DEPRECATED(msg) [[deprecated(msg)]]
#elif defined(_MSC_VER)
#define TEMC_DEPRECATED(msg) __declspec(deprecated(msg))
#elif defined(__GNUC__) || defined(__clang__)
#define TEMC_DEPRECATED(msg) __attribute__((deprecated(msg)))
#else
#define TEMC_DEPRECATED(msg)
#endif

/* The devices and filters this library has, as OIDN_DEVICE_* and OIDN_FILTER_* say for an
 * OIDN build: the CPU only (the GPU types are refused with
 * TEMC_ERROR_UNSUPPORTED_HARDWARE); "RT" and "RTLightmap". */
#if !defined(TEMC_DEVICE_CPU)
#define TEMC_DEVICE_CPU
#endif
#define TEMC_FILTER_RT
#define TEMC_FILTER_RTLIGHTMAP

#endif /* TEMC_CONFIG_H */
