#include "trailnav/runtime/arena.hpp"

#include <algorithm>
#include <cstring>

namespace trailnav {

// Each block starts with its header; blocks tile the storage, so the next
// block is at `size` bytes on and the previous one at `previous_size` back.
struct alignas(16) Arena::Header {
  std::size_t size;           // bytes of this block, header included (a multiple of 16)
  std::size_t previous_size;  // of the block before (0 for the first)
  std::uint32_t free;
};


namespace {
constexpr std::size_t kHeader = 32;  // sizeof(Arena::Header), checked in the constructor
constexpr std::size_t kMinBlock = 64;
std::size_t round16(std::size_t n) noexcept { return (n + 15u) & ~std::size_t{15}; }
}  // namespace

Arena::Arena(std::size_t bytes) {
  static_assert(sizeof(Header) == kHeader);
  capacity_ = std::max(round16(bytes), kMinBlock);
  storage_.reset(new std::byte[capacity_ + 16]);
  const auto addr = reinterpret_cast<std::uintptr_t>(storage_.get());
  base_ = storage_.get() + ((16u - (addr & 15u)) & 15u);
  std::memset(base_, 0, kHeader);
  Header* h = first();
  h->size = capacity_;
  h->previous_size = 0;
  h->free = 1;
}

Arena::Header* Arena::first() const noexcept { return reinterpret_cast<Header*>(base_); }

Arena::Header* Arena::next(Header* h) const noexcept {
  std::byte* n = reinterpret_cast<std::byte*>(h) + h->size;
  return n < base_ + capacity_ ? reinterpret_cast<Header*>(n) : nullptr;
}

Arena::Header* Arena::previous(Header* h) const noexcept {
  return h->previous_size == 0 ? nullptr : reinterpret_cast<Header*>(reinterpret_cast<std::byte*>(h) - h->previous_size);
}

bool Arena::owns(const void* p) const noexcept {
  const auto* b = static_cast<const std::byte*>(p);
  return b >= base_ && b < base_ + capacity_;
}

std::size_t Arena::usable_size(const void* p) const noexcept {
  return reinterpret_cast<const Header*>(static_cast<const std::byte*>(p) - kHeader)->size - kHeader;
}

// Cuts h to `size` bytes when the rest makes a block of its own.
void Arena::split(Header* h, std::size_t size) noexcept {
  if (h->size < size + kMinBlock) return;
  auto* rest = reinterpret_cast<Header*>(reinterpret_cast<std::byte*>(h) + size);
  rest->size = h->size - size;
  rest->previous_size = size;
  rest->free = 1;
  h->size = size;
  if (Header* after = next(rest)) {
    after->previous_size = rest->size;
    if (after->free != 0) {  // merge the new free block with a free one after it
      rest->size += after->size;
      if (Header* beyond = next(rest)) beyond->previous_size = rest->size;
    }
  }
}

void* Arena::allocate(std::size_t bytes) noexcept {
  const std::size_t need = round16(std::max<std::size_t>(bytes, 1)) + kHeader;
  for (Header* h = first(); h != nullptr; h = next(h)) {
    if (h->free == 0 || h->size < need) continue;
    split(h, need);
    h->free = 0;
    in_use_ += h->size;
    high_water_ = std::max(high_water_, in_use_);
    return reinterpret_cast<std::byte*>(h) + kHeader;
  }
  ++failures_;
  return nullptr;
}

void Arena::release(void* p) noexcept {
  if (p == nullptr) return;
  auto* h = reinterpret_cast<Header*>(static_cast<std::byte*>(p) - kHeader);
  in_use_ -= h->size;
  h->free = 1;
  if (Header* n = next(h); n != nullptr && n->free != 0) {
    h->size += n->size;
    if (Header* after = next(h)) after->previous_size = h->size;
  }
  if (Header* b = previous(h); b != nullptr && b->free != 0) {
    b->size += h->size;
    if (Header* after = next(b)) after->previous_size = b->size;
  }
}

void* Arena::reallocate(void* p, std::size_t bytes) noexcept {
  if (p == nullptr) return allocate(bytes);
  auto* h = reinterpret_cast<Header*>(static_cast<std::byte*>(p) - kHeader);
  const std::size_t need = round16(std::max<std::size_t>(bytes, 1)) + kHeader;
  if (h->size >= need) return p;  // shrinking keeps the block
  if (Header* n = next(h); n != nullptr && n->free != 0 && h->size + n->size >= need) {
    in_use_ += n->size;
    h->size += n->size;
    if (Header* after = next(h)) after->previous_size = h->size;
    const std::size_t before = h->size;
    split(h, need);
    in_use_ -= before - h->size;
    high_water_ = std::max(high_water_, in_use_);
    return p;
  }
  void* q = allocate(bytes);
  if (q == nullptr) return nullptr;
  std::memcpy(q, p, h->size - kHeader);
  release(p);
  return q;
}

}  // namespace trailnav
