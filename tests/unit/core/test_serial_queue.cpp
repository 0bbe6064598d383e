// SerialQueue: jobs from many threads run on the serving thread, one at a
// time, and their exceptions reach the thread that sent them. Also run under
// ThreadSanitizer (scripts/test).
#include "core/parallel.hpp"
#include "core/serial_queue.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

using namespace tigerlod;

TEST(SerialQueue, JobsFromWorkersRunOnTheServingThreadOneAtATime)
{
    SerialQueue queue;
    const auto server = std::this_thread::get_id();
    std::vector<std::thread::id> ran_on(64);
    std::vector<int> results(64, 0);
    int inside = 0, most_inside = 0; // touched only by jobs: the queue serialises them
    std::thread driver([&] {
        parallel_each(64, 4, [&](size_t i) {
            queue.run([&, i] {
                most_inside = std::max(most_inside, ++inside);
                ran_on[i] = std::this_thread::get_id();
                results[i] = int(i) * 2;
                --inside;
            });
        });
        queue.close();
    });
    queue.serve();
    driver.join();
    EXPECT_EQ(most_inside, 1);
    for (size_t i = 0; i < 64; ++i) {
        EXPECT_EQ(ran_on[i], server) << i;
        EXPECT_EQ(results[i], int(i) * 2);
    }
}

TEST(SerialQueue, AnExceptionReachesTheSenderAndServingGoesOn)
{
    SerialQueue queue;
    std::string caught;
    bool later_ran = false;
    std::thread sender([&] {
        try {
            queue.run([] { throw std::runtime_error("no context"); });
        } catch (const std::runtime_error& e) {
            caught = e.what();
        }
        queue.run([&] { later_ran = true; });
        queue.close();
    });
    queue.serve();
    sender.join();
    EXPECT_EQ(caught, "no context");
    EXPECT_TRUE(later_ran);
    EXPECT_THROW(queue.run([] {}), std::logic_error);
}
