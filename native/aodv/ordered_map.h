// A hash map that iterates in insertion order, as a Python dict does: assigning to a key
// that is present keeps its place, a key deleted and added again goes to the end. The
// protocol core's action order depends on that order (the routing table, the kernel's copy,
// the neighbours, the running discoveries, the duplicate-RREQ cache), so the compiled core
// keeps it exactly. Each entry carries the stamp of its insertion: sorting by stamp is
// sorting in dict order.
#pragma once

#include <cstdint>
#include <list>
#include <unordered_map>
#include <utility>

namespace aodv {

template <class K, class V>
class OrderedMap {
  public:
    struct Entry {
        K key;
        V value;
        uint64_t stamp;
    };
    using List = std::list<Entry>;
    using iterator = typename List::iterator;
    using const_iterator = typename List::const_iterator;

    V* find(const K& k) {
        auto it = index_.find(k);
        return it == index_.end() ? nullptr : &it->second->value;
    }
    const V* find(const K& k) const {
        auto it = index_.find(k);
        return it == index_.end() ? nullptr : &it->second->value;
    }
    bool contains(const K& k) const { return index_.count(k) != 0; }
    // The stamp of a present key (dict order), or UINT64_MAX.
    uint64_t stamp(const K& k) const {
        auto it = index_.find(k);
        return it == index_.end() ? UINT64_MAX : it->second->stamp;
    }
    // d[k] = v: in place if present, else at the end.
    V& assign(const K& k, V v) {
        auto it = index_.find(k);
        if (it != index_.end()) {
            it->second->value = std::move(v);
            return it->second->value;
        }
        items_.push_back(Entry{k, std::move(v), next_stamp_++});
        auto last = std::prev(items_.end());
        index_.emplace(k, last);
        return last->value;
    }
    bool erase(const K& k) {
        auto it = index_.find(k);
        if (it == index_.end()) return false;
        items_.erase(it->second);
        index_.erase(it);
        return true;
    }
    iterator erase(iterator it) {
        index_.erase(it->key);
        return items_.erase(it);
    }
    void clear() {
        items_.clear();
        index_.clear();
    }
    size_t size() const { return items_.size(); }
    bool empty() const { return items_.empty(); }
    iterator begin() { return items_.begin(); }
    iterator end() { return items_.end(); }
    const_iterator begin() const { return items_.begin(); }
    const_iterator end() const { return items_.end(); }

  private:
    List items_;
    std::unordered_map<K, iterator> index_;
    uint64_t next_stamp_ = 0;
};

}  // namespace aodv
