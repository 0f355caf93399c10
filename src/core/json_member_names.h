// A member name twice in one JSON object, found while the text is parsed (nlohmann's parser callback):
// JSON keeps the last value in silence, so a copy-paste ("beams": 256 ... "beams": 512) or a merge gone
// wrong (a second "nodes" array in a glTF) would lose one. The config and glTF loaders refuse it, naming it.
#pragma once

#include <cstddef>
#include <set>
#include <string>
#include <vector>

namespace vksonar {

class MemberNames {
public:
    // Called with every parse event (JsonT: nlohmann::json or ordered_json): each open object's names so
    // far, innermost last. Returns true (keep the value), as a parser callback must.
    template <class JsonT> bool on(typename JsonT::parse_event_t event, const JsonT& parsed) {
        using Event = typename JsonT::parse_event_t;
        if (event == Event::key) ++keys_;
        if (event == Event::object_start) {
            open_objects_.emplace_back();
        } else if (event == Event::object_end) {
            if (!open_objects_.empty()) open_objects_.pop_back();
        } else if (event == Event::key && !open_objects_.empty() && parsed.is_string()) {
            if (!open_objects_.back().insert(parsed.template get<std::string>()).second && twice_.empty())
                twice_ = parsed.template get<std::string>();
        }
        return true;
    }
    // The first name given twice in one object; empty if none.
    const std::string& twice() const { return twice_; }
    // Member names seen so far, all objects together.
    std::size_t keys() const { return keys_; }

private:
    std::vector<std::set<std::string>> open_objects_;
    std::string twice_;
    std::size_t keys_ = 0;
};

} // namespace vksonar
