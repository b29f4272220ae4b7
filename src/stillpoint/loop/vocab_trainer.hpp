#pragma once
// Training-set handling for the vocabulary: finds images in folders (plain image folders, TUM
// sequences through their rgb/ folder, dynsynth `places` output), extracts ORB descriptors with the
// system's own extractor (so training and run time see the same descriptor distribution) and trains.
#include <cstdint>
#include <filesystem>
#include <vector>

#include "stillpoint/loop/vocabulary.hpp"

namespace sp::loop {

struct VocabTrainingOptions {
  std::vector<std::filesystem::path> inputs;  // folders of images or TUM-layout sequence folders
  std::size_t max_images = 0;                 // 0 = all; otherwise evenly spaced over the sorted list [count]
  int features = 1000;                        // ORB keypoints per image [count], 100..10000
  VocabularyParams vocabulary;
  std::uint32_t seed = 1;
};

// Sorted image files (.png, .jpg, .jpeg) of every input (a folder with rgb/ contributes rgb/),
// thinned evenly to max_images. A missing folder or one without images is an sp::InputError.
std::vector<std::filesystem::path> collect_training_images(const std::vector<std::filesystem::path>& inputs,
                                                           std::size_t max_images);

// N x 32 ORB descriptors of each image (grey-scale), with sp::feat::OrbExtractor.
std::vector<cv::Mat> extract_training_descriptors(const std::vector<std::filesystem::path>& images,
                                                  int features);

struct VocabTrainingReport {
  std::size_t images = 0;
  std::size_t descriptors = 0;
  double extract_s = 0.0;
  double train_s = 0.0;
};

Vocabulary train_vocabulary(const VocabTrainingOptions& options, VocabTrainingReport* report = nullptr);

}  // namespace sp::loop
