// A growable byte buffer for the writers that format text or binary records layer by layer: no
// zero-filling, kept and reused from one layer to the next, written out with one call per layer.
#pragma once

#include <algorithm>
#include <charconv>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <string_view>
#include <utility>

namespace toposlice {

class TextBuffer {
 public:
  char* data() { return data_.get(); }
  const char* data() const { return data_.get(); }
  std::size_t size() const { return size_; }
  bool empty() const { return size_ == 0; }
  void clear() { size_ = 0; }
  void swap(TextBuffer& other) noexcept {
    std::swap(data_, other.data_);
    std::swap(capacity_, other.capacity_);
    std::swap(size_, other.size_);
  }
  // Makes room for `extra` more bytes and returns where they go; setEnd then marks how many were used.
  char* reserveMore(std::size_t extra) {
    if (size_ + extra > capacity_) grow(size_ + extra);
    return data_.get() + size_;
  }
  void setEnd(char* end) { size_ = static_cast<std::size_t>(end - data_.get()); }
  void append(std::string_view s) {
    std::memcpy(reserveMore(s.size()), s.data(), s.size());
    size_ += s.size();
  }
  void append(char c) {
    *reserveMore(1) = c;
    ++size_;
  }
  void append(const TextBuffer& t) { append(std::string_view(t.data(), t.size())); }
  void appendInt(int64_t v) {
    char* p = reserveMore(24);
    setEnd(std::to_chars(p, p + 24, v).ptr);
  }
  void appendUint(uint64_t v) {
    char* p = reserveMore(24);
    setEnd(std::to_chars(p, p + 24, v).ptr);
  }

 private:
  void grow(std::size_t need) {
    std::size_t capacity = std::max(capacity_ * 2, std::size_t{1} << 16);
    if (capacity < need) capacity = need;
    auto bigger = std::make_unique_for_overwrite<char[]>(capacity);
    if (size_ > 0) std::memcpy(bigger.get(), data_.get(), size_);
    data_ = std::move(bigger);
    capacity_ = capacity;
  }
  std::unique_ptr<char[]> data_;
  std::size_t capacity_ = 0;
  std::size_t size_ = 0;
};

}  // namespace toposlice
