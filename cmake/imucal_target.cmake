# Per-target compile settings: warnings (errors in CI), sanitizers. Never touches global flags.
function(imucal_setup_target target)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic -Wshadow -Wconversion)
  # GCC 12 reports false maybe-uninitialized and restrict warnings inside nlohmann::json, Eigen and
  # std::string once they are inlined at -O2/-O3 (GCC bugs 105562, 105329); both stay on in Debug.
  target_compile_options(${target} PRIVATE $<$<NOT:$<CONFIG:Debug>>:-Wno-maybe-uninitialized -Wno-restrict>)
  if(IMUCAL_WERROR)
    target_compile_options(${target} PRIVATE -Werror)
  endif()
  if(IMUCAL_SANITIZE)
    target_compile_options(${target} PRIVATE -fsanitize=address,undefined -fno-omit-frame-pointer
                                             -fno-sanitize-recover=undefined)
    target_link_options(${target} PRIVATE -fsanitize=address,undefined)
  endif()
endfunction()
