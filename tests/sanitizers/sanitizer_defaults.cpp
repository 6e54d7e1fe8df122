// Defaults for the ORGANFIT_SANITIZE build, compiled into every test binary and the app
// (the sanitizer runtimes call these hooks), so no environment variable is needed.
// Only findings inside third-party code are suppressed, each with its reason.

extern "C" const char* __ubsan_default_options() {
  // Every finding fatal and with a stack; pointer-overflow suppressions: ubsan.supp.
  return "print_stacktrace=1:halt_on_error=1:suppressions=" ORGANFIT_UBSAN_SUPPRESSIONS;
}

extern "C" const char* __lsan_default_suppressions() {
  // ITK 5.2's NRRD writer leaves its nrrd state (itk_nrrdNew, itk_biff messages) allocated
  // when a write fails (a folder that does not exist): about 3.5 KB per failed write.
  return "leak:itk_nrrdNew\n"
         "leak:itk_nrrdIoStateNew\n"
         "leak:itk_biffGet\n"
         "leak:itk_airArrayNew\n";
}
