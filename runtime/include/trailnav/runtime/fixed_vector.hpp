// Fixed-capacity vectors. The owner holds the storage; algorithms take
// std::span so they are not templated on the capacity.
#pragma once

#include <cassert>
#include <cstddef>
#include <memory>
#include <new>
#include <span>
#include <type_traits>
#include <utility>

namespace trailnav {

// Shared implementation over storage provided by the derived class.
template <typename T, typename Derived>
class FixedVectorBase {
 public:
  using value_type = T;
  using iterator = T*;
  using const_iterator = const T*;

  [[nodiscard]] std::size_t size() const noexcept { return size_; }
  [[nodiscard]] bool empty() const noexcept { return size_ == 0; }
  [[nodiscard]] bool full() const noexcept { return size_ == capacity(); }
  [[nodiscard]] std::size_t capacity() const noexcept { return self().capacity_impl(); }

  T* data() noexcept { return self().storage_impl(); }
  const T* data() const noexcept { return self().storage_impl(); }
  T& operator[](std::size_t i) noexcept { assert(i < size_); return data()[i]; }
  const T& operator[](std::size_t i) const noexcept { assert(i < size_); return data()[i]; }
  T& back() noexcept { assert(size_ > 0); return data()[size_ - 1]; }
  T* begin() noexcept { return data(); }
  T* end() noexcept { return data() + size_; }
  const T* begin() const noexcept { return data(); }
  const T* end() const noexcept { return data() + size_; }

  std::span<T> span() noexcept { return {data(), size_}; }
  std::span<const T> span() const noexcept { return {data(), size_}; }

  // Appends when there is room; returns false (and leaves the vector as it
  // was) when the vector is full.
  bool try_push_back(const T& value) noexcept(std::is_nothrow_copy_constructible_v<T>) {
    if (full()) return false;
    ::new (static_cast<void*>(data() + size_)) T(value);
    ++size_;
    return true;
  }

  // Constructs in place when there is room; nullptr when full.
  template <typename... Args>
  T* try_emplace_back(Args&&... args) noexcept(std::is_nothrow_constructible_v<T, Args...>) {
    if (full()) return nullptr;
    T* slot = ::new (static_cast<void*>(data() + size_)) T(std::forward<Args>(args)...);
    ++size_;
    return slot;
  }

  void pop_back() noexcept {
    assert(size_ > 0);
    --size_;
    std::destroy_at(data() + size_);
  }

  void clear() noexcept {
    std::destroy(data(), data() + size_);
    size_ = 0;
  }

  // Grows or shrinks to n elements (value-initialising new ones); n must not
  // exceed the capacity.
  void resize(std::size_t n) noexcept(std::is_nothrow_default_constructible_v<T>) {
    assert(n <= capacity());
    while (size_ > n) pop_back();
    while (size_ < n) {
      ::new (static_cast<void*>(data() + size_)) T();
      ++size_;
    }
  }

 protected:
  FixedVectorBase() = default;
  ~FixedVectorBase() = default;
  std::size_t size_ = 0;

 private:
  Derived& self() noexcept { return static_cast<Derived&>(*this); }
  const Derived& self() const noexcept { return static_cast<const Derived&>(*this); }
};

// Capacity fixed at compile time, storage inside the object.
template <typename T, std::size_t N>
class InlineVector : public FixedVectorBase<T, InlineVector<T, N>> {
  using Base = FixedVectorBase<T, InlineVector<T, N>>;
  friend Base;

 public:
  InlineVector() = default;
  InlineVector(const InlineVector& other) { copy_from(other); }
  InlineVector& operator=(const InlineVector& other) {
    if (this != &other) {
      this->clear();
      copy_from(other);
    }
    return *this;
  }
  ~InlineVector() { this->clear(); }

  static constexpr std::size_t static_capacity = N;

 private:
  void copy_from(const InlineVector& other) {
    for (const T& v : other) this->try_push_back(v);
  }
  std::size_t capacity_impl() const noexcept { return N; }
  T* storage_impl() noexcept { return std::launder(reinterpret_cast<T*>(storage_)); }
  const T* storage_impl() const noexcept {
    return std::launder(reinterpret_cast<const T*>(storage_));
  }

  alignas(T) std::byte storage_[sizeof(T) * N];
};

// Capacity chosen once at start-up (from the sensor model or the
// configuration); the storage is allocated by the constructor and never again.
template <typename T>
class FixedVector : public FixedVectorBase<T, FixedVector<T>> {
  using Base = FixedVectorBase<T, FixedVector<T>>;
  friend Base;

 public:
  explicit FixedVector(std::size_t capacity)
      : capacity_(capacity),
        storage_(static_cast<T*>(::operator new(sizeof(T) * capacity, std::align_val_t{alignof(T)}))) {}
  FixedVector(const FixedVector&) = delete;
  FixedVector& operator=(const FixedVector&) = delete;
  FixedVector(FixedVector&& other) noexcept
      : Base(), capacity_(std::exchange(other.capacity_, 0)), storage_(std::exchange(other.storage_, nullptr)) {
    this->size_ = std::exchange(other.size_, 0);
  }
  FixedVector& operator=(FixedVector&&) = delete;
  ~FixedVector() {
    this->clear();
    if (storage_ != nullptr) ::operator delete(storage_, std::align_val_t{alignof(T)});
  }

 private:
  std::size_t capacity_impl() const noexcept { return capacity_; }
  T* storage_impl() noexcept { return storage_; }
  const T* storage_impl() const noexcept { return storage_; }

  std::size_t capacity_;
  T* storage_;
};

}  // namespace trailnav
