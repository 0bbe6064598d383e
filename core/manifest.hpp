#pragma once
/// @file manifest.hpp
/// manifest.json: what every stage writes beside its outputs, saying how they
/// were made. It holds the stage, the tigerlod version and the library
/// versions, the resolved options that shape the outputs (never the thread
/// count or anything else the outputs do not depend on, so the manifest is as
/// deterministic as they are), and each input: the input folder's own
/// manifest digest, or for ingest the raw files' SHA-256.
///
/// A manifest's SHA-256 names its folder's content: the stages are
/// deterministic, so two folders with the same manifest hold the same bytes.
/// A stage that reads another's output reads its manifest first, records its
/// digest, and refuses inputs whose manifests disagree (a Data Tree packed
/// from another ingest than the one verify is given, colours made with other
/// options than simplify's). Schema: "tigerlod.manifest/1", described in
/// docs/stages.md (a stage's manifest.json).

#include <nlohmann/json.hpp>

#include <filesystem>
#include <string>
#include <vector>

namespace tigerlod {

/// One stage output's manifest as read back.
struct Manifest {
    std::filesystem::path folder;
    nlohmann::ordered_json doc;
    std::string sha256; ///< of the file's bytes: how a later stage names this input

    /// doc["options"][key]; throws input_error naming the file if absent.
    const nlohmann::ordered_json& option(const std::string& key) const;
    /// doc["inputs"][role]["sha256"]; throws input_error naming the file if absent.
    std::string input_sha256(const std::string& role) const;
};

/// A new manifest: schema, stage, version, libraries, empty inputs and options.
nlohmann::ordered_json new_manifest(const std::string& stage, const std::vector<std::string>& libraries);

/// Record `input` (another stage's output) as the input `role`: its stage and
/// manifest digest.
void add_input(nlohmann::ordered_json& manifest, const std::string& role, const Manifest& input);

/// Read `folder`/manifest.json, written by tigerlod-`stage`. Throws
/// input_error naming the folder if it is missing (not a finished output of
/// that stage, or one from before manifests: run the stage again), is not
/// JSON, or names another stage.
Manifest read_manifest(const std::filesystem::path& folder, const std::string& stage);

/// Throws input_error unless `made` was made from `input` as its input
/// `role`: the digests it recorded and the one `input` has now agree. The
/// message names both folders and what to run again.
void require_made_from(const Manifest& made, const std::string& role, const Manifest& input);

/// The manifest's text as written: two-space indented JSON and a newline.
std::string manifest_text(const nlohmann::ordered_json& manifest);

} // namespace tigerlod
