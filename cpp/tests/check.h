#pragma once
// A minimal test harness: CHECK records failures and keeps going; main()
// returns non-zero if any failed and prints "N passed, N failed".
#include <cmath>
#include <cstdio>
#include <functional>
#include <string>
#include <vector>

namespace check {
inline int& passed() { static int n = 0; return n; }
inline int& failed() { static int n = 0; return n; }
inline std::vector<std::pair<std::string, std::function<void()>>>& registry() {
  static std::vector<std::pair<std::string, std::function<void()>>> r;
  return r;
}
struct Register {
  Register(const char* name, std::function<void()> f) { registry().emplace_back(name, std::move(f)); }
};
inline int run_all() {
  for (auto& [name, f] : registry()) {
    const int before = failed();
    f();
    std::printf("%s %s\n", failed() == before ? "ok  " : "FAIL", name.c_str());
  }
  std::printf("%d passed, %d failed\n", passed(), failed());
  return failed() ? 1 : 0;
}
}  // namespace check

#define TEST(name)                                               \
  static void name();                                            \
  static check::Register reg_##name(#name, name);                \
  static void name()

#define CHECK(cond)                                                                  \
  do {                                                                               \
    if (cond) {                                                                      \
      ++check::passed();                                                             \
    } else {                                                                         \
      ++check::failed();                                                             \
      std::printf("  %s:%d: CHECK(%s) failed\n", __FILE__, __LINE__, #cond);         \
    }                                                                                \
  } while (0)

#define CHECK_CLOSE(a, b, tol)                                                                   \
  do {                                                                                           \
    const double va_ = (a), vb_ = (b);                                                           \
    if (std::abs(va_ - vb_) <= (tol)) {                                                          \
      ++check::passed();                                                                         \
    } else {                                                                                     \
      ++check::failed();                                                                         \
      std::printf("  %s:%d: |%s - %s| = |%g - %g| > %g\n", __FILE__, __LINE__, #a, #b, va_, vb_, \
                  double(tol));                                                                  \
    }                                                                                            \
  } while (0)

#define TEST_MAIN() \
  int main() { return check::run_all(); }
