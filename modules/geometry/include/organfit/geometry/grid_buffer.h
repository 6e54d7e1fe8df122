#pragma once
// A vector for a grid's values that a resize leaves unset: a grid of 80M doubles (640 MB,
// a million-particle body's reference) is then first written by the threads that fill it,
// each faulting in its own pages, instead of zeroed first on one thread. For buffers whose
// every element is written before it is read.
#include <memory>
#include <new>
#include <type_traits>
#include <utility>
#include <vector>

namespace organfit::geometry {

/// std::allocator, but constructing an element without a value leaves it unset.
template <class T, class Base = std::allocator<T>>
struct UnsetAllocator : Base {
  template <class U>
  struct rebind {
    using other = UnsetAllocator<U, typename std::allocator_traits<Base>::template rebind_alloc<U>>;
  };
  using Base::Base;
  template <class U>
  void construct(U* p) noexcept(std::is_nothrow_default_constructible_v<U>) {
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    std::allocator_traits<Base>::construct(static_cast<Base&>(*this), p,
                                           std::forward<Args>(args)...);
  }
};

/// A grid's values (i fastest), left unset by GridBuffer<T>(n).
template <class T>
using GridBuffer = std::vector<T, UnsetAllocator<T>>;

}  // namespace organfit::geometry
