#include "core/partitions.hpp"

#include "core/errors.hpp"

#include <fstream>
#include <sstream>

namespace tigerlod {

std::vector<std::string> list_items(const std::string& spec, const std::string& option)
{
    std::vector<std::string> items;
    if (spec.starts_with("@")) {
        std::ifstream in(spec.substr(1));
        if (!in) {
            throw input_error(spec.substr(1) + ": cannot read the list of " + option);
        }
        for (std::string line; std::getline(in, line);) {
            if (!line.empty() && line.back() == '\r') {
                line.pop_back();
            }
            if (!line.empty()) {
                items.push_back(line);
            }
        }
        return items;
    }
    std::stringstream ss(spec);
    for (std::string item; std::getline(ss, item, ',');) {
        items.push_back(item);
    }
    return items;
}

std::vector<bool> select_partitions(const std::vector<std::pair<std::string, std::string>>& stores,
                                    const std::string& spec, const std::filesystem::path& input)
{
    std::vector<bool> chosen(stores.size(), false);
    for (const std::string& item : list_items(spec, "--partitions")) {
        const auto slash = item.find('/');
        if (slash == std::string::npos || slash == 0 || slash + 1 == item.size()) {
            throw usage_error("option '--partitions' has '" + item +
                              "'; expected LEVEL/PARTITION, LEVEL/PREFIX* or LEVEL/*");
        }
        const std::string level = item.substr(0, slash);
        std::string name = item.substr(slash + 1);
        const bool prefix = name.ends_with("*");
        if (prefix) {
            name.pop_back();
        }
        bool any = false;
        for (size_t i = 0; i < stores.size(); ++i) {
            const auto& [l, p] = stores[i];
            if (l == level && (prefix ? p.starts_with(name) : p == name)) {
                chosen[i] = true;
                any = true;
            }
        }
        if (!any) {
            throw usage_error("option '--partitions' has '" + item + "', which matches no chain store of " +
                              input.string() + " (its stores are <level>/<partition>.tlc)");
        }
    }
    return chosen;
}

} // namespace tigerlod
