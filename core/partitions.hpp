#pragma once
/// @file partitions.hpp
/// `--partitions`: the stores a workflow job works on, as color, simplify
/// and pack take them.

#include <filesystem>
#include <string>
#include <utility>
#include <vector>

namespace tigerlod {

/// The items of a list option: items separated by commas, or `@FILE` with
/// one item a line (empty lines skipped). Throws input_error naming FILE,
/// and `option`, if FILE cannot be read.
std::vector<std::string> list_items(const std::string& spec, const std::string& option);

/// Which of `stores` (level, partition) `spec` names: items separated by
/// commas, or `@FILE` with one item a line; an item is `LEVEL/PARTITION`,
/// `LEVEL/PREFIX*` (the partitions of LEVEL whose names begin with PREFIX)
/// or `LEVEL/*`. Throws usage_error naming the item that matches no store of
/// `input` (a name misspelt, a partition that ingest did not write), and
/// input_error if FILE cannot be read.
std::vector<bool> select_partitions(const std::vector<std::pair<std::string, std::string>>& stores,
                                    const std::string& spec, const std::filesystem::path& input);

} // namespace tigerlod
