/* temc: neural denoiser for spectral Monte Carlo renders. Header-only C++11 wrapper over
 * temc.h with the surface of Intel Open Image Denoise 2.x's oidn.hpp under the temc
 * names: a renderer using oidn.hpp switches by renaming oidn/OIDN to temc/TEMC.
 *
 *   temc::DeviceRef device = temc::newDevice();            // the CPU
 *   device.commit();
 *   temc::BufferRef color = device.newBuffer(w * h * 3 * sizeof(float));
 *   temc::FilterRef filter = device.newFilter("RT");
 *   filter.setImage("color", color, temc::Format::Float3, w, h);
 *   filter.setImage("output", color, temc::Format::Float3, w, h); // in place
 *   filter.set("hdr", true);
 *   filter.commit();
 *   filter.execute();
 *   const char* message;
 *   if (device.getError(message) != temc::Error::None) ...
 *
 * Written for temc from OIDN's documented API; tests/c_header.rs compiles it against
 * temc.h and checks that every temc function and macro it uses exists there. */

#ifndef TEMC_HPP
#define TEMC_HPP

#include "temc.h"

#include <cassert>
#include <cstdint>
#include <cstring>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

TEMC_NAMESPACE_BEGIN

// ---------------------------------------------------------------------------------------
// Flags (a set of ExternalMemoryTypeFlag or ExternalSemaphoreTypeFlag values)

template <typename FlagT>
struct IsFlag {
  static constexpr bool value = false;
};

template <typename FlagT>
class Flags {
 public:
  static_assert(IsFlag<FlagT>::value, "not a flag type");
  using MaskType = typename std::underlying_type<FlagT>::type;

  constexpr Flags() noexcept : bits(0) {}
  constexpr Flags(FlagT flag) noexcept : bits(static_cast<MaskType>(flag)) {}
  constexpr explicit Flags(MaskType mask) noexcept : bits(mask) {}

  constexpr bool operator!() const noexcept { return bits == 0; }
  constexpr explicit operator bool() const noexcept { return bits != 0; }
  constexpr explicit operator MaskType() const noexcept { return bits; }
  constexpr Flags operator&(const Flags& o) const noexcept { return Flags(MaskType(bits & o.bits)); }
  constexpr Flags operator|(const Flags& o) const noexcept { return Flags(MaskType(bits | o.bits)); }
  constexpr Flags operator^(const Flags& o) const noexcept { return Flags(MaskType(bits ^ o.bits)); }
  Flags& operator&=(const Flags& o) noexcept { bits &= o.bits; return *this; }
  Flags& operator|=(const Flags& o) noexcept { bits |= o.bits; return *this; }
  Flags& operator^=(const Flags& o) noexcept { bits ^= o.bits; return *this; }
  constexpr bool operator==(const Flags& o) const noexcept { return bits == o.bits; }
  constexpr bool operator!=(const Flags& o) const noexcept { return bits != o.bits; }

 private:
  MaskType bits;
};

template <typename FlagT, typename std::enable_if<IsFlag<FlagT>::value, bool>::type = true>
constexpr Flags<FlagT> operator|(FlagT a, FlagT b) noexcept { return Flags<FlagT>(a) | Flags<FlagT>(b); }
template <typename FlagT, typename std::enable_if<IsFlag<FlagT>::value, bool>::type = true>
constexpr Flags<FlagT> operator&(FlagT a, FlagT b) noexcept { return Flags<FlagT>(a) & Flags<FlagT>(b); }
template <typename FlagT, typename std::enable_if<IsFlag<FlagT>::value, bool>::type = true>
constexpr Flags<FlagT> operator^(FlagT a, FlagT b) noexcept { return Flags<FlagT>(a) ^ Flags<FlagT>(b); }

// ---------------------------------------------------------------------------------------
// Enumerations (the C values)

enum class Format : uint32_t {
  Undefined = TEMC_FORMAT_UNDEFINED,
  Float = TEMC_FORMAT_FLOAT,
  Float2 = TEMC_FORMAT_FLOAT2,
  Float3 = TEMC_FORMAT_FLOAT3,
  Float4 = TEMC_FORMAT_FLOAT4,
  Half = TEMC_FORMAT_HALF,
  Half2 = TEMC_FORMAT_HALF2,
  Half3 = TEMC_FORMAT_HALF3,
  Half4 = TEMC_FORMAT_HALF4,
};

enum class Storage : uint32_t {
  Undefined = TEMC_STORAGE_UNDEFINED,
  Host = TEMC_STORAGE_HOST,
  Device = TEMC_STORAGE_DEVICE,
  Managed = TEMC_STORAGE_MANAGED,
};

enum class ExternalMemoryTypeFlag : uint32_t {
  None = TEMC_EXTERNAL_MEMORY_TYPE_FLAG_NONE,
  OpaqueFD = TEMC_EXTERNAL_MEMORY_TYPE_FLAG_OPAQUE_FD,
  DMABuf = TEMC_EXTERNAL_MEMORY_TYPE_FLAG_DMA_BUF,
  OpaqueWin32 = TEMC_EXTERNAL_MEMORY_TYPE_FLAG_OPAQUE_WIN32,
  OpaqueWin32KMT = TEMC_EXTERNAL_MEMORY_TYPE_FLAG_OPAQUE_WIN32_KMT,
  D3D11Texture = TEMC_EXTERNAL_MEMORY_TYPE_FLAG_D3D11_TEXTURE,
  D3D11TextureKMT = TEMC_EXTERNAL_MEMORY_TYPE_FLAG_D3D11_TEXTURE_KMT,
  D3D11Resource = TEMC_EXTERNAL_MEMORY_TYPE_FLAG_D3D11_RESOURCE,
  D3D11ResourceKMT = TEMC_EXTERNAL_MEMORY_TYPE_FLAG_D3D11_RESOURCE_KMT,
  D3D12Heap = TEMC_EXTERNAL_MEMORY_TYPE_FLAG_D3D12_HEAP,
  D3D12Resource = TEMC_EXTERNAL_MEMORY_TYPE_FLAG_D3D12_RESOURCE,
};

template <>
struct IsFlag<ExternalMemoryTypeFlag> {
  static constexpr bool value = true;
};
using ExternalMemoryTypeFlags = Flags<ExternalMemoryTypeFlag>;

/// External semaphore types (OIDN 2.5), for DeviceRef::newSemaphore; the CPU device
/// imports none ("externalSemaphoreTypes" is 0).
enum class ExternalSemaphoreTypeFlag : uint32_t {
  None = TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_NONE,
  OpaqueFD = TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_OPAQUE_FD,
  OpaqueWin32 = TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_OPAQUE_WIN32,
  OpaqueWin32KMT = TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_OPAQUE_WIN32_KMT,
  D3D11Fence = TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_D3D11_FENCE,
  D3D12Fence = TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_D3D12_FENCE,
  KeyedMutex = TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_KEYED_MUTEX,
  KeyedMutexKMT = TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_KEYED_MUTEX_KMT,
  TimelineSemaphoreFD = TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_TIMELINE_SEMAPHORE_FD,
  TimelineSemaphoreWin32 = TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_TIMELINE_SEMAPHORE_WIN32,
};

template <>
struct IsFlag<ExternalSemaphoreTypeFlag> {
  static constexpr bool value = true;
};
using ExternalSemaphoreTypeFlags = Flags<ExternalSemaphoreTypeFlag>;

enum class Quality : uint32_t {
  Default = TEMC_QUALITY_DEFAULT,
  Fast = TEMC_QUALITY_FAST,
  Balanced = TEMC_QUALITY_BALANCED,
  High = TEMC_QUALITY_HIGH,
};

enum class DeviceType : uint32_t {
  Default = TEMC_DEVICE_TYPE_DEFAULT,
  CPU = TEMC_DEVICE_TYPE_CPU,
  SYCL = TEMC_DEVICE_TYPE_SYCL,
  CUDA = TEMC_DEVICE_TYPE_CUDA,
  HIP = TEMC_DEVICE_TYPE_HIP,
  Metal = TEMC_DEVICE_TYPE_METAL,
};

enum class Error : uint32_t {
  None = TEMC_ERROR_NONE,
  Unknown = TEMC_ERROR_UNKNOWN,
  InvalidArgument = TEMC_ERROR_INVALID_ARGUMENT,
  InvalidOperation = TEMC_ERROR_INVALID_OPERATION,
  OutOfMemory = TEMC_ERROR_OUT_OF_MEMORY,
  UnsupportedHardware = TEMC_ERROR_UNSUPPORTED_HARDWARE,
  Cancelled = TEMC_ERROR_CANCELLED,
};

// The enum classes have the C types' width, so callbacks taking them match the C ones.
static_assert(sizeof(Error) == sizeof(TEMCError), "Error must match TEMCError");

/// Error callback: user pointer, code, message (valid during the call).
typedef void (*ErrorFunction)(void* userPtr, Error code, const char* message);

/// Progress callback: return false to cancel.
using ProgressMonitorFunction = TEMCProgressMonitorFunction;

/// Opaque universally unique identifier of a physical device.
struct UUID {
  uint8_t bytes[TEMC_UUID_SIZE];
};

/// Opaque locally unique identifier of a physical device.
struct LUID {
  union {
#if defined(__GNUC__)
    __extension__  // an anonymous struct, as OIDN's (low, high) members need
#endif
    struct {
      uint32_t low;
      int32_t high;
    };
    uint8_t bytes[TEMC_LUID_SIZE];
  };
};

// ---------------------------------------------------------------------------------------
// Reference-counted handles

namespace detail {

// How each handle type is retained and released.
template <typename H>
struct HandleTraits;

template <>
struct HandleTraits<TEMCDevice> {
  static void retain(TEMCDevice h) { temcRetainDevice(h); }
  static void release(TEMCDevice h) { temcReleaseDevice(h); }
};

template <>
struct HandleTraits<TEMCFilter> {
  static void retain(TEMCFilter h) { temcRetainFilter(h); }
  static void release(TEMCFilter h) { temcReleaseFilter(h); }
};

template <>
struct HandleTraits<TEMCBuffer> {
  static void retain(TEMCBuffer h) { temcRetainBuffer(h); }
  static void release(TEMCBuffer h) { temcReleaseBuffer(h); }
};

template <>
struct HandleTraits<TEMCSemaphore> {
  static void retain(TEMCSemaphore h) { temcRetainSemaphore(h); }
  static void release(TEMCSemaphore h) { temcReleaseSemaphore(h); }
};

// Owns one reference to a handle; copies retain, moves transfer, destruction releases.
// Constructing from a raw handle adopts the reference the caller got from a New call;
// assigning a raw handle retains it (the caller keeps its own reference).
template <typename H>
class Ref {
 public:
  Ref() noexcept : h(nullptr) {}
  Ref(H handle) noexcept : h(handle) {}
  Ref(const Ref& o) noexcept : h(o.h) { if (h) HandleTraits<H>::retain(h); }
  Ref(Ref&& o) noexcept : h(o.h) { o.h = nullptr; }
  ~Ref() { if (h) HandleTraits<H>::release(h); }

  Ref& operator=(const Ref& o) noexcept {
    if (this != &o) reset(o.h, true);
    return *this;
  }
  Ref& operator=(Ref&& o) noexcept {
    std::swap(h, o.h);
    return *this;
  }
  Ref& operator=(H other) noexcept {
    reset(other, true);
    return *this;
  }

  H getHandle() const noexcept { return h; }
  operator bool() const noexcept { return h != nullptr; }

  /// Drops this reference now.
  void release() noexcept { reset(nullptr, false); }

 protected:
  H h;

 private:
  void reset(H other, bool retain) noexcept {
    if (other && retain) HandleTraits<H>::retain(other);
    if (h) HandleTraits<H>::release(h);
    h = other;
  }
};

}  // namespace detail

// ---------------------------------------------------------------------------------------
// Buffer

/// A buffer (host memory on temc's CPU device).
class BufferRef : public detail::Ref<TEMCBuffer> {
 public:
  using detail::Ref<TEMCBuffer>::Ref;
  using detail::Ref<TEMCBuffer>::operator=;
  BufferRef() noexcept = default;

  size_t getSize() const { return temcGetBufferSize(h); }
  Storage getStorage() const { return static_cast<Storage>(temcGetBufferStorage(h)); }
  void* getData() const { return temcGetBufferData(h); }

  void read(size_t byteOffset, size_t byteSize, void* dstHostPtr) const {
    temcReadBuffer(h, byteOffset, byteSize, dstHostPtr);
  }
  void readAsync(size_t byteOffset, size_t byteSize, void* dstHostPtr) const {
    temcReadBufferAsync(h, byteOffset, byteSize, dstHostPtr);
  }
  void write(size_t byteOffset, size_t byteSize, const void* srcHostPtr) {
    temcWriteBuffer(h, byteOffset, byteSize, srcHostPtr);
  }
  void writeAsync(size_t byteOffset, size_t byteSize, const void* srcHostPtr) {
    temcWriteBufferAsync(h, byteOffset, byteSize, srcHostPtr);
  }
};

// ---------------------------------------------------------------------------------------
// Filter

/// A filter ("RT", "RTLightmap", "TEMC2", ...).
class FilterRef : public detail::Ref<TEMCFilter> {
 public:
  using detail::Ref<TEMCFilter>::Ref;
  using detail::Ref<TEMCFilter>::operator=;
  FilterRef() noexcept = default;

  /// An image stored in a buffer.
  void setImage(const char* name, const BufferRef& buffer, Format format, size_t width,
                size_t height, size_t byteOffset = 0, size_t pixelByteStride = 0,
                size_t rowByteStride = 0) {
    temcSetFilterImage(h, name, buffer.getHandle(), static_cast<TEMCFormat>(format), width,
                       height, byteOffset, pixelByteStride, rowByteStride);
  }

  /// An image in the caller's memory.
  void setImage(const char* name, void* devPtr, Format format, size_t width, size_t height,
                size_t byteOffset = 0, size_t pixelByteStride = 0, size_t rowByteStride = 0) {
    temcSetSharedFilterImage(h, name, devPtr, static_cast<TEMCFormat>(format), width, height,
                             byteOffset, pixelByteStride, rowByteStride);
  }

  void unsetImage(const char* name) { temcUnsetFilterImage(h, name); }
  TEMC_DEPRECATED("removeImage is deprecated: use unsetImage")
  void removeImage(const char* name) { temcUnsetFilterImage(h, name); }

  void setData(const char* name, void* hostPtr, size_t byteSize) {
    temcSetSharedFilterData(h, name, hostPtr, byteSize);
  }
  void updateData(const char* name) { temcUpdateFilterData(h, name); }
  void unsetData(const char* name) { temcUnsetFilterData(h, name); }
  TEMC_DEPRECATED("removeData is deprecated: use unsetData")
  void removeData(const char* name) { temcUnsetFilterData(h, name); }

  void set(const char* name, bool value) { temcSetFilterBool(h, name, value); }
  void set(const char* name, int value) { temcSetFilterInt(h, name, value); }
  void set(const char* name, Quality value) {
    temcSetFilterInt(h, name, static_cast<int>(value));
  }
  void set(const char* name, float value) { temcSetFilterFloat(h, name, value); }

  /// Reads a parameter: T is bool, int, Quality or float.
  template <typename T>
  T get(const char* name) const;

  void setProgressMonitorFunction(ProgressMonitorFunction func, void* userPtr = nullptr) {
    temcSetFilterProgressMonitorFunction(h, func, userPtr);
  }

  void commit() { temcCommitFilter(h); }
  void execute() { temcExecuteFilter(h); }
  /// Queued on the device; returns at once (DeviceRef::sync waits for it).
  void executeAsync() { temcExecuteFilterAsync(h); }
};

template <>
inline bool FilterRef::get<bool>(const char* name) const { return temcGetFilterBool(h, name); }
template <>
inline int FilterRef::get<int>(const char* name) const { return temcGetFilterInt(h, name); }
template <>
inline Quality FilterRef::get<Quality>(const char* name) const {
  return static_cast<Quality>(temcGetFilterInt(h, name));
}
template <>
inline float FilterRef::get<float>(const char* name) const { return temcGetFilterFloat(h, name); }

// ---------------------------------------------------------------------------------------
// Semaphore (OIDN 2.5)

/// An imported external semaphore. temc's CPU device imports none, so
/// DeviceRef::newSemaphore gives a null one (and an error); the class is here for code
/// written against OIDN 2.5 to build and take its no-semaphore path.
class SemaphoreRef : public detail::Ref<TEMCSemaphore> {
 public:
  using detail::Ref<TEMCSemaphore>::Ref;
  using detail::Ref<TEMCSemaphore>::operator=;
  SemaphoreRef() noexcept = default;
};

// ---------------------------------------------------------------------------------------
// Device

/// A device (temc has one kind: the CPU).
class DeviceRef : public detail::Ref<TEMCDevice> {
 public:
  using detail::Ref<TEMCDevice>::Ref;
  using detail::Ref<TEMCDevice>::operator=;
  DeviceRef() noexcept = default;

  void set(const char* name, bool value) { temcSetDeviceBool(h, name, value); }
  void set(const char* name, int value) { temcSetDeviceInt(h, name, value); }
  void set(const char* name, unsigned int value) { temcSetDeviceUInt(h, name, value); }

  /// Reads a parameter: T is bool, int, unsigned int, DeviceType, ExternalMemoryTypeFlags
  /// or ExternalSemaphoreTypeFlags.
  template <typename T>
  T get(const char* name) const;

  void setErrorFunction(ErrorFunction func, void* userPtr = nullptr) {
    // Error has TEMCError's representation (static_assert above), so the C library may
    // call a function taking Error.
    temcSetDeviceErrorFunction(h, reinterpret_cast<TEMCErrorFunction>(func), userPtr);
  }

  /// The first unqueried error (then cleared); a null device gives this thread's global one.
  Error getError() { return static_cast<Error>(temcGetDeviceError(h, nullptr)); }
  Error getError(const char*& outMessage) {
    return static_cast<Error>(temcGetDeviceError(h, &outMessage));
  }

  void commit() { temcCommitDevice(h); }
  void sync() { temcSyncDevice(h); }

  BufferRef newBuffer(size_t byteSize) const { return temcNewBuffer(h, byteSize); }
  BufferRef newBuffer(size_t byteSize, Storage storage) const {
    return temcNewBufferWithStorage(h, byteSize, static_cast<TEMCStorage>(storage));
  }
  /// A buffer over the caller's memory.
  BufferRef newBuffer(void* ptr, size_t byteSize) const {
    return temcNewSharedBuffer(h, ptr, byteSize);
  }
  /// External memory: refused by the CPU device (a null buffer and an error).
  BufferRef newBuffer(ExternalMemoryTypeFlag fdType, int fd, size_t byteSize) const {
    return temcNewSharedBufferFromFD(h, static_cast<TEMCExternalMemoryTypeFlag>(fdType), fd,
                                     byteSize);
  }
  BufferRef newBuffer(ExternalMemoryTypeFlag handleType, void* handle, const void* name,
                      size_t byteSize) const {
    return temcNewSharedBufferFromWin32Handle(
        h, static_cast<TEMCExternalMemoryTypeFlag>(handleType), handle, name, byteSize);
  }

  FilterRef newFilter(const char* type) const { return temcNewFilter(h, type); }

  /// Imports an external semaphore (OIDN 2.5): refused by the CPU device, whose
  /// "externalSemaphoreTypes" is 0 (a null semaphore and an error; the fd stays yours).
  SemaphoreRef newSemaphore(ExternalSemaphoreTypeFlags fdType, int fd) const {
    return temcNewSharedSemaphoreFromFD(
        h, static_cast<TEMCExternalSemaphoreTypeFlags>(
               static_cast<ExternalSemaphoreTypeFlags::MaskType>(fdType)),
        fd);
  }
  SemaphoreRef newSemaphore(ExternalSemaphoreTypeFlags handleType, void* handle,
                            const void* name) const {
    return temcNewSharedSemaphoreFromWin32Handle(
        h, static_cast<TEMCExternalSemaphoreTypeFlags>(
               static_cast<ExternalSemaphoreTypeFlags::MaskType>(handleType)),
        handle, name);
  }

  /// Signals semaphores once the work queued so far is done; `values` (empty, or one per
  /// semaphore) are the timeline/fence values or keyed-mutex keys. No semaphore can exist
  /// on the CPU device, so this reports TEMC_ERROR_INVALID_OPERATION.
  void signalSemaphoresAsync(const std::vector<SemaphoreRef>& semaphores,
                             const std::vector<uint64_t>& values = std::vector<uint64_t>()) {
    assert(values.empty() || values.size() == semaphores.size());
    std::vector<TEMCSemaphore> handles = rawSemaphores(semaphores);
    temcSignalSemaphoresAsync(h, handles.data(), values.empty() ? nullptr : values.data(),
                              static_cast<int>(handles.size()));
  }
  void signalSemaphoreAsync(const SemaphoreRef& semaphore, uint64_t value = 0) {
    TEMCSemaphore handle = semaphore.getHandle();
    temcSignalSemaphoresAsync(h, &handle, &value, 1);
  }

  /// Makes later work wait for semaphores; `values` and `timeoutsMs` are empty or one per
  /// semaphore. As signalSemaphoresAsync, refused by the CPU device.
  void waitSemaphoresAsync(const std::vector<SemaphoreRef>& semaphores,
                           const std::vector<uint64_t>& values = std::vector<uint64_t>(),
                           const std::vector<uint32_t>& timeoutsMs = std::vector<uint32_t>()) {
    assert(values.empty() || values.size() == semaphores.size());
    assert(timeoutsMs.empty() || timeoutsMs.size() == semaphores.size());
    std::vector<TEMCSemaphore> handles = rawSemaphores(semaphores);
    temcWaitSemaphoresAsync(h, handles.data(), values.empty() ? nullptr : values.data(),
                            timeoutsMs.empty() ? nullptr : timeoutsMs.data(),
                            static_cast<int>(handles.size()));
  }
  void waitSemaphoreAsync(const SemaphoreRef& semaphore, uint64_t value = 0) {
    TEMCSemaphore handle = semaphore.getHandle();
    temcWaitSemaphoresAsync(h, &handle, &value, nullptr, 1);
  }

 private:
  static std::vector<TEMCSemaphore> rawSemaphores(const std::vector<SemaphoreRef>& semaphores) {
    std::vector<TEMCSemaphore> handles;
    handles.reserve(semaphores.size());
    for (const SemaphoreRef& s : semaphores) handles.push_back(s.getHandle());
    return handles;
  }
};

template <>
inline bool DeviceRef::get<bool>(const char* name) const { return temcGetDeviceBool(h, name); }
template <>
inline int DeviceRef::get<int>(const char* name) const { return temcGetDeviceInt(h, name); }
template <>
inline unsigned int DeviceRef::get<unsigned int>(const char* name) const {
  return temcGetDeviceUInt(h, name);
}
template <>
inline DeviceType DeviceRef::get<DeviceType>(const char* name) const {
  return static_cast<DeviceType>(temcGetDeviceInt(h, name));
}
template <>
inline ExternalMemoryTypeFlags DeviceRef::get<ExternalMemoryTypeFlags>(const char* name) const {
  return ExternalMemoryTypeFlags(
      static_cast<ExternalMemoryTypeFlags::MaskType>(temcGetDeviceInt(h, name)));
}
template <>
inline ExternalSemaphoreTypeFlags DeviceRef::get<ExternalSemaphoreTypeFlags>(
    const char* name) const {
  return ExternalSemaphoreTypeFlags(
      static_cast<ExternalSemaphoreTypeFlags::MaskType>(temcGetDeviceInt(h, name)));
}

/// This thread's global error (device creation, released handles), then cleared.
inline Error getError() { return static_cast<Error>(temcGetDeviceError(nullptr, nullptr)); }
inline Error getError(const char*& outMessage) {
  return static_cast<Error>(temcGetDeviceError(nullptr, &outMessage));
}

inline DeviceRef newDevice(DeviceType type = DeviceType::Default) {
  return DeviceRef(temcNewDevice(static_cast<TEMCDeviceType>(type)));
}
inline DeviceRef newDevice(int physicalDeviceID) {
  return DeviceRef(temcNewDeviceByID(physicalDeviceID));
}
inline DeviceRef newDevice(const UUID& uuid) { return DeviceRef(temcNewDeviceByUUID(uuid.bytes)); }
inline DeviceRef newDevice(const LUID& luid) { return DeviceRef(temcNewDeviceByLUID(luid.bytes)); }
inline DeviceRef newDevice(int pciDomain, int pciBus, int pciDevice, int pciFunction) {
  return DeviceRef(temcNewDeviceByPCIAddress(pciDomain, pciBus, pciDevice, pciFunction));
}

// The GPU constructors exist so GPU-capable renderers build; they return a null device
// with TEMC_ERROR_UNSUPPORTED_HARDWARE.
inline DeviceRef newCUDADevice(int deviceID, cudaStream_t stream) {
  return DeviceRef(temcNewCUDADevice(&deviceID, &stream, 1));
}
inline DeviceRef newCUDADevice(const std::vector<int>& deviceIDs,
                               const std::vector<cudaStream_t>& streams) {
  assert(deviceIDs.size() == streams.size());
  return DeviceRef(
      temcNewCUDADevice(deviceIDs.data(), streams.data(), static_cast<int>(streams.size())));
}
inline DeviceRef newHIPDevice(int deviceID, hipStream_t stream) {
  return DeviceRef(temcNewHIPDevice(&deviceID, &stream, 1));
}
inline DeviceRef newHIPDevice(const std::vector<int>& deviceIDs,
                              const std::vector<hipStream_t>& streams) {
  assert(deviceIDs.size() == streams.size());
  return DeviceRef(
      temcNewHIPDevice(deviceIDs.data(), streams.data(), static_cast<int>(streams.size())));
}
#if !defined(__OBJC__)
inline DeviceRef newMetalDevice(MTLCommandQueue_id commandQueue) {
  return DeviceRef(temcNewMetalDevice(&commandQueue, 1));
}
inline DeviceRef newMetalDevice(const std::vector<MTLCommandQueue_id>& commandQueues) {
  return DeviceRef(
      temcNewMetalDevice(commandQueues.data(), static_cast<int>(commandQueues.size())));
}
#endif

inline bool isCPUDeviceSupported() { return temcIsCPUDeviceSupported(); }
inline bool isCUDADeviceSupported(int deviceID) { return temcIsCUDADeviceSupported(deviceID); }
inline bool isHIPDeviceSupported(int deviceID) { return temcIsHIPDeviceSupported(deviceID); }
#if !defined(__OBJC__)
inline bool isMetalDeviceSupported(MTLDevice_id device) {
  return temcIsMetalDeviceSupported(device);
}
#endif

// ---------------------------------------------------------------------------------------
// Physical devices (temc has one: ID 0, the CPU)

class PhysicalDeviceRef {
 public:
  PhysicalDeviceRef() : id(-1) {}
  PhysicalDeviceRef(int id) : id(id) {}
  PhysicalDeviceRef& operator=(int other) {
    id = other;
    return *this;
  }

  int getID() const { return id; }
  operator bool() const { return id >= 0; }

  /// Reads a parameter: T is bool, int, unsigned int, DeviceType, const char*,
  /// std::string, UUID or LUID.
  template <typename T>
  T get(const char* name) const;

  /// Opaque data (pointer, size); the CPU has no UUID or LUID: (nullptr, 0) and an error.
  std::pair<const void*, size_t> getData(const char* name) const {
    size_t size = 0;
    const void* p = temcGetPhysicalDeviceData(id, name, &size);
    return std::make_pair(p, size);
  }

  DeviceRef newDevice() { return DeviceRef(temcNewDeviceByID(id)); }

 private:
  int id;

  template <typename T>
  T getBytes(const char* name) const {
    T v;
    std::memset(&v, 0, sizeof v);
    std::pair<const void*, size_t> d = getData(name);
    if (d.first && d.second == sizeof v.bytes) std::memcpy(v.bytes, d.first, sizeof v.bytes);
    return v;
  }
};

inline int getNumPhysicalDevices() { return temcGetNumPhysicalDevices(); }

template <>
inline bool PhysicalDeviceRef::get<bool>(const char* name) const {
  return temcGetPhysicalDeviceBool(id, name);
}
template <>
inline int PhysicalDeviceRef::get<int>(const char* name) const {
  return temcGetPhysicalDeviceInt(id, name);
}
template <>
inline unsigned int PhysicalDeviceRef::get<unsigned int>(const char* name) const {
  return temcGetPhysicalDeviceUInt(id, name);
}
template <>
inline DeviceType PhysicalDeviceRef::get<DeviceType>(const char* name) const {
  return static_cast<DeviceType>(temcGetPhysicalDeviceInt(id, name));
}
template <>
inline const char* PhysicalDeviceRef::get<const char*>(const char* name) const {
  return temcGetPhysicalDeviceString(id, name);
}
template <>
inline std::string PhysicalDeviceRef::get<std::string>(const char* name) const {
  const char* s = temcGetPhysicalDeviceString(id, name);
  return s ? std::string(s) : std::string();
}
template <>
inline UUID PhysicalDeviceRef::get<UUID>(const char* name) const { return getBytes<UUID>(name); }
template <>
inline LUID PhysicalDeviceRef::get<LUID>(const char* name) const { return getBytes<LUID>(name); }

TEMC_NAMESPACE_END

#endif /* TEMC_HPP */
