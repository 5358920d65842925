// An open-addressing table of doubles by 64-bit code, shared by the compiled optimum programmes
// (pile.cpp, optimal.cpp): 16-byte slots, linear probing, at most half full.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <new>
#include <utility>

namespace opportune_memo {

inline uint64_t mix(uint64_t x) {  // the splitmix64 finaliser: a well-spread slot for every code
    x ^= x >> 30;
    x *= 0xbf58476d1ce4e5b9ULL;
    x ^= x >> 27;
    x *= 0x94d049bb133111ebULL;
    return x ^ (x >> 31);
}

// Values by code: linear probing, power-of-two capacity, at most half full.  The slots come zeroed
// from calloc (a large block is mapped lazily by the system: reserving is immediate, a page is paid for
// when first written), so a code is kept as code + 1 and 0 marks an empty slot.
class Table {
public:
    struct Slot {
        uint64_t key;
        double val;
    };
    Table() { rehash(1024); }
    ~Table() { std::free(slots_); }
    Table(const Table&) = delete;
    Table& operator=(const Table&) = delete;
    const double* find(uint64_t code) const {
        uint64_t key = code + 1;
        for (size_t i = mix(key) & mask_;; i = (i + 1) & mask_) {
            if (slots_[i].key == key) return &slots_[i].val;
            if (slots_[i].key == 0) return nullptr;
        }
    }
    void put(uint64_t code, double v) {
        if (2 * (size_ + 1) > cap_) rehash(cap_ * 2);
        uint64_t key = code + 1;
        for (size_t i = mix(key) & mask_;; i = (i + 1) & mask_) {
            if (slots_[i].key == key || slots_[i].key == 0) {
                size_ += slots_[i].key == 0;
                slots_[i].key = key;
                slots_[i].val = v;
                return;
            }
        }
    }
    void reserve(size_t n) {
        size_t cap = cap_;
        while (cap < 2 * n) cap *= 2;
        if (cap > cap_) rehash(cap);
    }
    size_t size() const { return size_; }
    // the bytes of a table reserved for n values (what reserve(n) allocates on a new table)
    static size_t bytes_for(size_t n) {
        size_t cap = 1024;
        while (cap < 2 * n) cap *= 2;
        return cap * sizeof(Slot);
    }
    size_t bytes() const { return cap_ * sizeof(Slot); }

private:
    void rehash(size_t cap) {
        Slot* slots = static_cast<Slot*>(std::calloc(cap, sizeof(Slot)));
        if (!slots) throw std::bad_alloc();
        size_t m = cap - 1;
        for (size_t j = 0; j < cap_; ++j) {
            if (slots_[j].key == 0) continue;
            size_t i = mix(slots_[j].key) & m;
            while (slots[i].key != 0) i = (i + 1) & m;
            slots[i] = slots_[j];
        }
        std::free(slots_);
        slots_ = slots;
        cap_ = cap;
        mask_ = m;
    }
    Slot* slots_ = nullptr;
    size_t cap_ = 0, mask_ = 0, size_ = 0;
};

struct PairHash {
    size_t operator()(const std::pair<uint64_t, uint64_t>& k) const { return mix(k.first ^ mix(k.second)); }
};

}  // namespace opportune_memo
