// A robot-centred grid that moves with the robot without copying.
//
// Every cell has a fixed world index (floor of its world coordinate over the
// resolution). The storage is a torus: world index (ix, iy) lives at storage
// column ix mod size_x and row iy mod size_y. Moving the map only changes the
// world index of its lowest corner (the origin) and clears the storage rows
// and columns whose world cells just came into view, so a move costs time in
// proportion to the cells cleared, never to the grid size. The storage is
// allocated once, by the constructor.
#pragma once

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <span>
#include <type_traits>

namespace trailnav {

struct CellIndex {
  std::int32_t x = 0;
  std::int32_t y = 0;
  friend bool operator==(const CellIndex&, const CellIndex&) = default;
};

struct WorldPoint {
  double x = 0.0;
  double y = 0.0;
};

template <typename Cell>
class RollingGrid {
 public:
  // size_x by size_y cells of `resolution` metres; every cell starts as `empty`.
  RollingGrid(std::int32_t size_x, std::int32_t size_y, double resolution, const Cell& empty = Cell{})
      : size_x_(size_x),
        size_y_(size_y),
        resolution_(resolution),
        inverse_resolution_(1.0 / resolution),
        empty_(empty),
        cells_(std::make_unique<Cell[]>(static_cast<std::size_t>(size_x) * static_cast<std::size_t>(size_y))) {
    assert(size_x > 0 && size_y > 0 && resolution > 0.0);
    fill(empty_);
  }

  std::int32_t size_x() const noexcept { return size_x_; }
  std::int32_t size_y() const noexcept { return size_y_; }
  std::size_t cell_count() const noexcept { return static_cast<std::size_t>(size_x_) * static_cast<std::size_t>(size_y_); }
  double resolution() const noexcept { return resolution_; }
  // World index of the map's lowest-x, lowest-y cell.
  CellIndex origin() const noexcept { return origin_; }
  const Cell& empty_value() const noexcept { return empty_; }

  CellIndex world_to_index(double x, double y) const noexcept {
    return {static_cast<std::int32_t>(std::floor(x * inverse_resolution_)),
            static_cast<std::int32_t>(std::floor(y * inverse_resolution_))};
  }
  WorldPoint cell_center(CellIndex i) const noexcept {
    return {(i.x + 0.5) * resolution_, (i.y + 0.5) * resolution_};
  }
  bool contains(CellIndex i) const noexcept {
    return i.x >= origin_.x && i.x < origin_.x + size_x_ && i.y >= origin_.y && i.y < origin_.y + size_y_;
  }

  // Precondition: contains(i).
  Cell& at(CellIndex i) noexcept {
    assert(contains(i));
    return cells_[storage_offset(i)];
  }
  const Cell& at(CellIndex i) const noexcept {
    assert(contains(i));
    return cells_[storage_offset(i)];
  }
  // The cell under a world point, or nullptr outside the map.
  Cell* find(double x, double y) noexcept {
    const CellIndex i = world_to_index(x, y);
    return contains(i) ? &cells_[storage_offset(i)] : nullptr;
  }
  const Cell* find(double x, double y) const noexcept {
    const CellIndex i = world_to_index(x, y);
    return contains(i) ? &cells_[storage_offset(i)] : nullptr;
  }

  // Re-centres the map on world point (x, y). Returns the number of cells cleared.
  std::size_t move_to(double x, double y) noexcept {
    const CellIndex centre = world_to_index(x, y);
    return move_origin_to({centre.x - size_x_ / 2, centre.y - size_y_ / 2});
  }

  // Moves the origin; storage cells whose world cell is new are set to empty.
  std::size_t move_origin_to(CellIndex new_origin) noexcept {
    std::size_t cleared = 0;
    const std::int64_t dx = std::int64_t{new_origin.x} - origin_.x;
    const std::int64_t dy = std::int64_t{new_origin.y} - origin_.y;
    if (std::llabs(dx) >= size_x_ || std::llabs(dy) >= size_y_) {
      set_origin(new_origin);
      fill(empty_);
      return cell_count();
    }
    // Columns entering along x: clear them over every storage row (all of
    // those cells are new, whatever the y move does next).
    if (dx != 0) {
      const std::int32_t first = dx > 0 ? origin_.x + size_x_ : new_origin.x;
      const auto count = static_cast<std::int32_t>(std::llabs(dx));
      for (std::int32_t wx = first; wx < first + count; ++wx) cleared += clear_storage_column(wrap(wx, size_x_));
    }
    set_origin({new_origin.x, origin_.y});
    if (dy != 0) {
      const std::int32_t first = dy > 0 ? origin_.y + size_y_ : new_origin.y;
      const auto count = static_cast<std::int32_t>(std::llabs(dy));
      for (std::int32_t wy = first; wy < first + count; ++wy) cleared += clear_storage_row(wrap(wy, size_y_));
    }
    set_origin(new_origin);
    return cleared;
  }

  // Becomes a copy of `other`, which must have the same size (no allocation).
  void assign_from(const RollingGrid& other) noexcept {
    assert(other.size_x_ == size_x_ && other.size_y_ == size_y_);
    resolution_ = other.resolution_;
    inverse_resolution_ = other.inverse_resolution_;
    empty_ = other.empty_;
    set_origin(other.origin_);
    std::copy(other.cells_.get(), other.cells_.get() + cell_count(), cells_.get());
  }

  void fill(const Cell& value) noexcept {
    std::fill(cells_.get(), cells_.get() + cell_count(), value);
  }

  // Calls f(CellIndex, Cell&) for every cell of [lo, hi) that lies in the
  // map, row by row.
  template <typename F>
  void for_each_in_window(CellIndex lo, CellIndex hi, F&& f) {
    const std::int32_t x0 = std::max(lo.x, origin_.x);
    const std::int32_t x1 = std::min(hi.x, origin_.x + size_x_);
    const std::int32_t y0 = std::max(lo.y, origin_.y);
    const std::int32_t y1 = std::min(hi.y, origin_.y + size_y_);
    if (x0 >= x1) return;
    const std::int32_t first = wrap(x0, size_x_);  // the storage column of x0; later ones follow, wrapping once
    for (std::int32_t y = y0; y < y1; ++y) {
      Cell* row = cells_.get() + static_cast<std::size_t>(wrap(y, size_y_)) * static_cast<std::size_t>(size_x_);
      std::int32_t column = first;
      for (std::int32_t x = x0; x < x1; ++x) {
        f(CellIndex{x, y}, row[column]);
        if (++column == size_x_) column = 0;
      }
    }
  }

  // A cell's place in the storage. Two grids of the same size moved to the
  // same origins hold the cells of one world index at the same offset, so a
  // companion grid (a cache of derived values) can follow a main grid.
  std::size_t offset_of(const Cell& c) const noexcept { return static_cast<std::size_t>(&c - cells_.get()); }
  Cell& at_offset(std::size_t offset) noexcept { return cells_[offset]; }
  const Cell& at_offset(std::size_t offset) const noexcept { return cells_[offset]; }
  // The storage offset of the cell `dx` columns and `dy` rows from the
  // origin. Precondition: 0 <= dx < size_x, 0 <= dy < size_y.
  std::size_t offset_from_origin(std::int32_t dx, std::int32_t dy) const noexcept {
    assert(dx >= 0 && dx < size_x_ && dy >= 0 && dy < size_y_);
    return storage_offset({origin_.x + dx, origin_.y + dy});
  }

  // Copies the map into `out` (size_x * size_y cells) in row-major order
  // starting at the origin: out[(y - origin.y) * size_x + (x - origin.x)].
  void copy_to(std::span<Cell> out) const noexcept {
    assert(out.size() >= cell_count());
    const auto sx0 = static_cast<std::size_t>(wrap(origin_.x, size_x_));
    const auto w = static_cast<std::size_t>(size_x_);
    for (std::int32_t row = 0; row < size_y_; ++row) {
      const Cell* src = cells_.get() + static_cast<std::size_t>(wrap(origin_.y + row, size_y_)) * w;
      Cell* dst = out.data() + static_cast<std::size_t>(row) * w;
      std::copy(src + sx0, src + w, dst);
      std::copy(src, src + sx0, dst + (w - sx0));
    }
  }

 private:
  static std::int32_t wrap(std::int32_t v, std::int32_t n) noexcept {
    const std::int32_t r = v % n;
    return r < 0 ? r + n : r;
  }
  // Precondition: contains(i). No division: the cell's offset from the
  // origin plus the origin's storage position, wrapped once.
  std::size_t storage_offset(CellIndex i) const noexcept {
    std::int32_t sx = i.x - origin_.x + origin_storage_.x;
    if (sx >= size_x_) sx -= size_x_;
    std::int32_t sy = i.y - origin_.y + origin_storage_.y;
    if (sy >= size_y_) sy -= size_y_;
    return static_cast<std::size_t>(sy) * static_cast<std::size_t>(size_x_) + static_cast<std::size_t>(sx);
  }
  void set_origin(CellIndex o) noexcept {
    origin_ = o;
    origin_storage_ = {wrap(o.x, size_x_), wrap(o.y, size_y_)};
  }
  std::size_t clear_storage_column(std::int32_t sx) noexcept {
    const auto w = static_cast<std::size_t>(size_x_);
    for (std::size_t row = 0; row < static_cast<std::size_t>(size_y_); ++row) cells_[row * w + static_cast<std::size_t>(sx)] = empty_;
    return static_cast<std::size_t>(size_y_);
  }
  std::size_t clear_storage_row(std::int32_t sy) noexcept {
    Cell* row = cells_.get() + static_cast<std::size_t>(sy) * static_cast<std::size_t>(size_x_);
    std::fill(row, row + size_x_, empty_);
    return static_cast<std::size_t>(size_x_);
  }

  std::int32_t size_x_;
  std::int32_t size_y_;
  double resolution_;
  double inverse_resolution_;
  Cell empty_;
  CellIndex origin_{};
  CellIndex origin_storage_{};  // where the origin's cell lives in storage
  std::unique_ptr<Cell[]> cells_;
};

}  // namespace trailnav
