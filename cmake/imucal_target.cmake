# Per-target compile settings: warnings (errors in CI), sanitizers. Never touches global flags.
function(imucal_setup_target target)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic -Wshadow -Wconversion)
  # GCC 12 reports false maybe-uninitialized and restrict warnings inside nlohmann::json, Eigen and
  # std::string once they are inlined at -O2/-O3 (GCC bugs 105562, 105329); both stay on in Debug.
  target_compile_options(${target} PRIVATE $<$<NOT:$<CONFIG:Debug>>:-Wno-maybe-uninitialized -Wno-restrict>)
  # Unity builds: a target's sources compiled eight to a translation unit, so the Eigen, JSON,
  # Asio and gtest headers they share are parsed, and their templates instantiated and optimised,
  # once per eight files instead of once per file (the estimators library: 263 s of one core in
  # sixteen sanitizer compiles, 107 s in two). Inside a unity file GCC sees each source as a header,
  # so a private type in an anonymous namespace used by a class's Impl draws -Wsubobject-linkage.
  if(IMUCAL_UNITY)
    set_target_properties(${target} PROPERTIES UNITY_BUILD ON UNITY_BUILD_BATCH_SIZE 8)
    target_compile_options(${target} PRIVATE -Wno-subobject-linkage)
  endif()
  if(IMUCAL_WERROR)
    target_compile_options(${target} PRIVATE -Werror)
  endif()
  if(IMUCAL_SANITIZE)
    # UBSan without the five checks that instrument every memory access, pointer step and virtual
    # call: they doubled the instrumented build's compile time (daemon/http/http_server.cpp 106 s of
    # one core with them, 56 s without, 55 s for ASan alone). ASan already reports what null,
    # object-size and pointer-overflow look for (a null or out-of-bounds access); alignment guards
    # type punning the code does not do (its reinterpret_casts are to bytes and sockaddr); vptr
    # guards a virtual call through an object of the wrong type. The checks kept are those of
    # arithmetic and values: signed overflow, shifts, division by zero, float-to-int overflow,
    # array bounds, bool and enum loads, missing returns, unreachable, builtin misuse.
    set(ubsan_skipped null,alignment,object-size,pointer-overflow,vptr)
    target_compile_options(${target} PRIVATE -fsanitize=address,undefined -fno-sanitize=${ubsan_skipped}
                                             -fno-omit-frame-pointer -fno-sanitize-recover=undefined)
    target_link_options(${target} PRIVATE -fsanitize=address,undefined -fno-sanitize=${ubsan_skipped})
  endif()
endfunction()
